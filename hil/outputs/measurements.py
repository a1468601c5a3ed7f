"""A trial's results as measurements in the manner of OpenHTF: a name, a value, a unit, a limit and an
outcome (PASS, FAIL, or not judged when the config sets no limit for it).

The trial passes when no judged measurement fails; a judged measurement without a value (e.g. a bias
that was not observable) fails.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hil.config import ReportLimits
from hil.estimation.table_reference import drifts_agree
from hil.vocabulary import Verdict

PASS, FAIL, NOT_JUDGED = Verdict.PASS, Verdict.FAIL, "not judged"
SIGMA_DIGITS = 2  # significant digits of a value's sigma that set the decimals it is shown with
SIGNIFICANT = 3  # significant digits of a value shown without a sigma
# the measurements of the streams themselves, whatever the estimators made of them
STREAM_MEASUREMENTS = frozenset({"frames_dropped", "frames_corrupt", "imu_missing_fraction", "imu_gated_fraction",
                                 "imu_invalid_fraction", "imu_without_angles_fraction", "sync_offset"})


@dataclass(frozen=True)
class Measurement:
    """One result of the trial, judged against its limit (OpenHTF style)."""

    name: str
    value: float | int | bool | None
    unit: str
    limit: str  # human-readable validator, "" when not judged
    outcome: str  # PASS, FAIL or NOT_JUDGED
    description: str = ""
    sigma: float | None = None  # 1-sigma of the value, in its unit, when the trial knows it

    @property
    def shown(self) -> str:
        """The value as every output shows it (:func:`format_value`: to its sigma's precision)."""
        return format_value(self.value, self.sigma)


def _at_most(name, value, unit, bound, description="", absolute=False, sigma=None) -> Measurement:
    """A measurement judged by ``value <= bound`` (``|value| <= bound`` when absolute); bound None: not judged."""
    if bound is None:
        return Measurement(name, value, unit, "", NOT_JUDGED, description, sigma)
    limit = f"{'|x| ' if absolute else ''}≤ {format_value(bound)}"
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return Measurement(name, value, unit, limit, FAIL, description, sigma)
    ok = (abs(value) if absolute else value) <= bound
    return Measurement(name, value, unit, limit, PASS if ok else FAIL, description, sigma)


def _info(name, value, unit, description="", sigma=None) -> Measurement:
    return Measurement(name, value, unit, "", NOT_JUDGED, description, sigma)


def drift_not_the_accelerometer(result: dict) -> bool | None:
    """Whether a drift the self-calibration sees (its drift check significant, or the drift model fitted) is
    missing from the table-referenced fit (:func:`~hil.estimation.table_reference.drifts_agree`): then it is
    not the accelerometer's but the gyros' errors, integrated into the attitude over the trial (the
    self-calibration takes the gyros as perfect). None without both drift estimates."""
    check = result.get("estimate", {}).get("drift_check")
    table = result.get("table_reference") or {}
    if not check or table.get("accel_bias_drift_ug_per_h") is None:
        return None
    flagged = check["significant"] or result["estimate"].get("bias_model") == "drift"
    return flagged and not drifts_agree(check["drift_ug_per_h"], check["sigma_ug_per_h"],
                                        table["accel_bias_drift_ug_per_h"], table["accel_bias_drift_sigma_ug_per_h"])


def measurements(result: dict, limits: ReportLimits) -> list[Measurement]:
    """The trial's measurements from a result.json document, judged against ``limits``."""
    est = result.get("estimate", {})
    bias = est.get("accel_bias_ug") or [None] * 3
    sigma = est.get("accel_bias_sigma_ug") or [None] * 3
    truth = (result.get("truth") or {}).get("accel_bias_ug")
    out: list[Measurement] = []
    for k, axis in enumerate("xyz"):
        out.append(_info(f"accel_bias_{axis}", bias[k], "µg", f"accelerometer bias estimate, {axis} axis", sigma[k]))
    for k, axis in enumerate("xyz"):
        out.append(_at_most(f"accel_bias_sigma_{axis}", sigma[k], "µg", limits.bias_sigma_ug_max,
                            f"1σ of the bias estimate, {axis} axis"))  # fmt: skip
    if truth is not None:
        # the truth is the bias at the start: with the drift model, compare the estimate of b_s
        drift_model = est.get("bias_model") == "drift"
        start = (est.get("accel_bias_t0_ug") or [None] * 3) if drift_model else bias
        start_sigma = (est.get("accel_bias_t0_sigma_ug") or [None] * 3) if drift_model else sigma
        for k, axis in enumerate("xyz"):
            error = None if start[k] is None else start[k] - truth[k]
            out.append(_at_most(f"accel_bias_error_{axis}", error, "µg", limits.bias_error_ug_max,
                                f"estimate − truth ({format_value(truth[k])} µg), {axis} axis", absolute=True,
                                sigma=start_sigma[k]))  # fmt: skip
    elif limits.bias_error_ug_max is not None:
        out.append(Measurement("accel_bias_error", None, "µg", f"|x| ≤ {format_value(limits.bias_error_ug_max)}", NOT_JUDGED,
                               "no truth: the bias error is judged on emulated trials only"))  # fmt: skip
    out.append(_info("bias_observable", est.get("observable"), "", "scaled Gram matrix of full rank"))
    out.append(_info("gram_rank", est.get("gram_rank"), "of 12", "rank of the scaled Gram matrix (2019 eq. 19)"))
    if "gram_condition" in est:  # null when the matrix is singular
        out.append(_info("gram_condition", est["gram_condition"], "", "condition number of the scaled Gram matrix"))
    converged, bound = est.get("converged_at_s"), limits.converged_by_s
    what = "first solve after which every estimate is settled: 3σ and its distance to each later one within 10 µg"
    duration = (result.get("trial") or {}).get("duration_s") or 0.0
    if converged is None and bound is not None and duration < bound:
        out.append(Measurement("converged_at", None, "s", f"≤ {format_value(bound)}", NOT_JUDGED,
                               f"not converged yet when the trial ended at {format_value(duration)} s, before the "
                               f"limit: {what}"))
    else:
        out.append(_at_most("converged_at", converged, "s", bound, what))
    drift = est.get("accel_bias_drift_ug_per_h")
    if drift is not None:
        sigma_k = est.get("accel_bias_drift_sigma_ug_per_h") or [None] * 3
        for k, axis in enumerate("xyz"):
            out.append(_info(f"accel_bias_drift_{axis}", drift[k], "µg/h", f"bias drift rate ±{format_value(sigma_k[k])} "
                             f"(1σ), {axis} axis (2018 gravity-vector paper, b = b_s + k t)", sigma_k[k]))
    check = est.get("drift_check")
    if check is not None:
        out.append(_info("bias_drift_significant", check["significant"], "",
                         "15-state drift check: some axis drifts beyond 4σ ("
                         + ", ".join(format_value(v) for v in check["drift_ug_per_h"]) + " µg/h)"))
    gyros = drift_not_the_accelerometer(result)
    if gyros is not None:
        table_drift = result["table_reference"]["accel_bias_drift_ug_per_h"]
        out.append(_info("bias_drift_not_in_table_reference", gyros, "",
                         "a drift the self-calibration sees that the table-referenced fit ("
                         + ", ".join(format_value(v) for v in table_drift)
                         + " µg/h) does not: the gyros' errors turning the attitude, not the accelerometer"))
    if est.get("noise_ug") is not None:
        out.append(_info("accel_noise", est["noise_ug"], "µg", "residual RMS per axis and sample"))

    alignment = result.get("alignment_deg") or {}
    method2 = alignment.get("method2") or {}
    for angle in ("pitch", "roll"):
        out.append(_at_most(f"alignment_method2_{angle}", method2.get(angle), "deg", limits.method2_error_deg_max,
                            f"method-2 {angle} error against the turntable, mean of the last 10 %",
                            absolute=True))  # fmt: skip
    if "yaw" in method2:
        out.append(_info("alignment_method2_yaw", method2["yaw"], "deg", "method-2 yaw error, mean of the last 10 %"))
    for method, angles in (("method1", ("pitch", "roll", "yaw")), ("theoretical", ("pitch", "roll"))):
        values = alignment.get(method) or {}
        for angle in angles:
            if angle in values:
                out.append(_info(f"alignment_{method}_{angle}", values[angle], "deg",
                                 f"{'method-1' if method == 'method1' else 'theoretical (2019 eq. 8)'} {angle} error"))  # fmt: skip

    table = (result.get("table_reference") or {}).get("accel_bias_ug")
    if table is not None:
        table_sigma = result["table_reference"].get("accel_bias_sigma_ug") or [None] * 3
        for k, axis in enumerate("xyz"):
            out.append(_info(f"table_referenced_bias_{axis}", table[k], "µg", "bias from the turntable attitude",
                             table_sigma[k]))

    calibration = result.get("calibration")
    if calibration is not None:
        out.append(_at_most("calibration_residual_max", calibration["residual_max_ug"], "µg",
                            limits.calibration_residual_ug_max, "largest specific-force residual at a position, "
                            "after calibration (calibration.json)"))
        out.append(_at_most("calibration_error_worst", calibration["worst_error_sigma"], "σ",
                            limits.calibration_error_sigma_max if "truth" in result else None,
                            "largest |estimate − truth| of an observable term, in its 1σ (emulated trials)"))
    streams = result.get("streams") or {}
    out.append(_at_most("frames_dropped", streams.get("dropped"), "frames", limits.dropped_max, "frames lost"))
    out.append(_at_most("frames_corrupt", streams.get("corrupt"), "frames", limits.corrupt_max,
                        "frames with a bad checksum or framing"))  # fmt: skip
    out += _judged_data(streams, limits)
    for key, value in streams.items():
        if key == "sync" and value:
            out += [_info(f"stream_sync_{k}", len(v) if isinstance(v, list) else v, "", "sync pairing")
                    for k, v in value.items()]
        elif key == "imu_temperature_c":
            out += [_info(f"imu_temperature_{k}", v, "°C", f"the IMU's own temperature, {k} over the trial")
                    for k, v in (value or {}).items()]
        elif key == "imu_invalid_by_flag":
            out += [_info(f"imu_invalid_{flag}", n, "", "samples the IMU flagged so") for flag, n in value.items()]
        elif key == "gyro_rate_error_dph":
            out += [_info(f"gyro_rate_error_{axis}", v, "°/h", f"gyro rate minus the table's, {axis} axis: the gyro "
                          "bias, plus scale factor and misalignment times the rate of a turning axis")
                    for axis, v in zip("xyz", value or ())]  # fmt: skip
        elif key not in ("dropped", "corrupt", "sync"):
            out.append(_info(f"stream_{key}", value, "frames" if "frames" in key else "", "stream counter"))
    return out


def _judged_data(streams: dict, limits: ReportLimits) -> list[Measurement]:
    """The aligned streams' own judgement (a simulation's are not aligned): the fractions of the IMU samples
    filled or bridged, gated, flagged invalid by the IMU and without angles, and the sync offset between the
    streams."""
    if "aligner_aligned" not in streams:
        return []
    aligned, bridged = streams["aligner_aligned"], streams["aligner_imu_bridged"]
    slots = max(aligned + bridged, 1)
    out = [_at_most("imu_missing_fraction", (streams["aligner_imu_filled"] + bridged) / slots, "", limits.missing_max,
                    "IMU samples filled or bridged (their frames lost), of all"),
           _at_most("imu_gated_fraction", streams["imu_gated"] / slots, "", limits.gated_max,
                    "IMU samples the gyro/table gate removed, of all"),
           _at_most("imu_invalid_fraction", streams.get("imu_invalid", 0) / slots, "", limits.invalid_max,
                    "IMU samples the IMU's own status flagged invalid (never estimated), of all"),
           _at_most("imu_without_angles_fraction", streams["aligner_without_angles"] / slots, "",
                    limits.without_angles_max, "IMU samples aligned without table angles, of all")]
    offset = streams.get("sync_offset_ms")
    what = "lag of the table's angles behind the IMU, from the gyros against the table's rate"
    if offset is None:
        out.append(Measurement("sync_offset", None, "ms", "", NOT_JUDGED, f"{what}: no motion to measure it by"))
    else:
        out.append(_at_most("sync_offset", offset, "ms", limits.sync_offset_ms_max, what, absolute=True))
    return out


def overall(results: list[Measurement]) -> str:
    """PASS when no judged measurement failed."""
    return FAIL if any(m.outcome == FAIL for m in results) else PASS


def format_value(value, sigma: float | None = None) -> str:
    """A value as report.html, junit.xml (and so the CI plugin) and the limits show it: with a ``sigma``, to the
    decimals of the sigma's first ``SIGMA_DIGITS`` significant digits (60.3 with a sigma of 1.5, 60.31 with
    0.15); without one, to ``SIGNIFICANT`` significant digits (1.53), in powers of ten below 1e-3 and from 1e5."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return value
    if isinstance(value, int):
        return str(value)
    if not math.isfinite(value):
        return str(value)
    if sigma is not None and math.isfinite(sigma) and sigma > 0:
        text = f"{value:.{_decimals(sigma, SIGMA_DIGITS)}f}"
    elif value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e5):
        return f"{value:.{SIGNIFICANT - 1}e}"
    else:
        text = f"{value:.{_decimals(value, SIGNIFICANT)}f}"
        text = text.rstrip("0").rstrip(".") if "." in text else text  # no sigma: its zeros say nothing
    return text.lstrip("-") if float(text) == 0 else text  # never -0


def _decimals(x: float, digits: int) -> int:
    """The decimals that show ``x`` to ``digits`` significant digits (none for the units of a large x)."""
    return max(0, digits - 1 - math.floor(math.log10(abs(x)))) if x else digits - 1


def rate_test_measurements(doc: dict, limits: ReportLimits) -> list[Measurement]:
    """The measurements of a rate-table test's document (scale_factor.json or frequency_response.json) per gyro
    axis, the scale factor test's judged against ``limits``; an axis the test could not fit has no values."""
    out: list[Measurement] = []
    for axis, a in doc["axes"].items():
        if doc["test"] == "scale_factor":
            out += [_at_most(f"scale_factor_error_{axis}", a.get("scale_factor_ppm"), "ppm", limits.scale_factor_ppm_max,
                             f"scale factor minus nominal, gyro {axis}", True, a.get("scale_factor_sigma_ppm")),
                    _at_most(f"nonlinearity_{axis}", a.get("nonlinearity_ppm"), "ppm", limits.nonlinearity_ppm_max,
                             f"largest residual, of full-scale output, gyro {axis}"),
                    _at_most(f"asymmetry_{axis}", a.get("asymmetry_ppm"), "ppm", limits.asymmetry_ppm_max,
                             f"|K+ − K−| / K, gyro {axis}", sigma=a.get("asymmetry_sigma_ppm")),
                    _info(f"bias_{axis}", a.get("bias_dph"), "°/h", f"zero-rate bias, gyro {axis}", a.get("bias_sigma_dph"))]
            left = [f"{s['rate_dps']:g} °/s: {s['left_out']}" for s in a.get("steps", []) if s.get("left_out")]
            if left or a.get("unfitted"):
                why = "; ".join(left + ([f"not fitted: {a['unfitted']}"] if a.get("unfitted") else []))
                out.append(_info(f"steps_left_out_{axis}", len(left), "", f"steps left out of the fit, gyro {axis}: {why}"))
        else:
            out += [_info(f"bandwidth_{axis}", a.get("bandwidth_hz"), "Hz",
                          f"-3 dB bandwidth, gyro {axis} ({a.get('bandwidth_note') or 'fitted'})", a.get("bandwidth_sigma_hz")),
                    _info(f"damping_{axis}", a.get("damping"), "", f"damping ratio, gyro {axis}", a.get("damping_sigma")),
                    _info(f"delay_{axis}", a.get("delay_ms"), "ms", f"pure delay, gyro {axis}", a.get("delay_sigma_ms")),
                    _info(f"delay_vs_latch_{axis}", a.get("latch_check"), "", "the delay against the stated latch delays")]
    return out
