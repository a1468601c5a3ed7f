"""A trial's results as measurements in the manner of OpenHTF: a name, a value, a unit, a limit and an
outcome (PASS, FAIL, or not judged when the config sets no limit for it).

Each measurement is declared once in :data:`DECLARED`: its name, its unit, how it is read from a result.json
document and the key of ``output.limits`` that judges it. :func:`measurements` reads them all, once a trial
(:mod:`hil.outputs.judgement`), for report.html, junit.xml, the viewer's verdict and the history; the pytest
plugin names a trial's measurements from the same table.

The trial passes when no judged measurement fails; a judged measurement without a value (e.g. a bias
that was not observable) fails.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

from hil.config import ReportLimits
from hil.estimation.table_reference import drifts_agree
from hil.vocabulary import Verdict

PASS, FAIL, NOT_JUDGED = Verdict.PASS, Verdict.FAIL, "not judged"
SIGMA_DIGITS = 2  # significant digits of a value's sigma that set the decimals it is shown with
SIGNIFICANT = 3  # significant digits of a value shown without a sigma
AXES = "xyz"
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
    limit = _limit_text(bound, absolute)
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return Measurement(name, value, unit, limit, FAIL, description, sigma)
    ok = (abs(value) if absolute else value) <= bound
    return Measurement(name, value, unit, limit, PASS if ok else FAIL, description, sigma)


def _limit_text(bound: float, absolute: bool) -> str:
    """A limit as the outputs show it: ``≤ bound``, ``|x| ≤ bound`` on an absolute value."""
    return f"{'|x| ' if absolute else ''}≤ {format_value(bound)}"


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


class Limit(Enum):
    """How a reading meets its measurement's limit."""

    JUDGED = "judged"  # judged against it
    SHOWN = "shown"  # shown beside it, not judged (and no row at all when no limit is set)
    NONE = "none"  # no limit applies to this trial


@dataclass(frozen=True)
class Reading:
    """What a declared measurement reads of a result.json document: a value, what it is, its 1-sigma, its name's
    ``suffix`` (an axis's ``_x``; a counter's whole name), its ``unit`` where it varies (None: the declared one), and
    how its limit meets it."""

    value: Any
    description: str
    sigma: float | None = None
    suffix: str = ""
    unit: str | None = None
    limit: Limit = Limit.JUDGED


@dataclass(frozen=True)
class Declared:
    """One measurement (or one per axis, per counter) declared once: its ``name``, its ``unit``, how it is ``read``
    from a result.json document (no reading: the trial has no such measurement), the key of ``output.limits`` that
    judges it (None: informational), whether that bounds its absolute value, and for a time limit ``pending``: what
    a value not reached yet is called when the trial ended before the limit (not judged then)."""

    name: str
    unit: str
    read: Callable[[dict], list[Reading]]
    limit: str | None = None
    absolute: bool = False
    pending: str = ""


def _estimate(result: dict) -> dict:
    return result.get("estimate", {})


def _axes(values: list | None, description: str, sigmas: list | None = None) -> list[Reading]:
    """A reading per axis of ``values`` (None: none on any axis), ``{axis}`` in ``description`` named."""
    values, sigmas = values or [None] * 3, sigmas or [None] * 3
    return [Reading(values[k], description.format(axis=a), sigmas[k], f"_{a}") for k, a in enumerate(AXES)]


def _one(value: Any, description: str, present: bool = True) -> list[Reading]:
    """One reading of ``value``, or none when the trial has no such measurement (not ``present``)."""
    return [Reading(value, description)] if present else []


def _bias_error(result: dict) -> list[Reading]:
    """Estimate minus truth per axis; the truth is the bias at the start: with the drift model, the estimate of
    b_s is compared. Without a truth, a reading that says so (a limit set for it is shown, not judged)."""
    truth = (result.get("truth") or {}).get("accel_bias_ug")
    if truth is None:
        return [Reading(None, "no truth: the bias error is judged on emulated trials only", limit=Limit.SHOWN)]
    est = _estimate(result)
    t0 = est.get("bias_model") == "drift"
    start = (est.get("accel_bias_t0_ug") if t0 else est.get("accel_bias_ug")) or [None] * 3
    sigma = (est.get("accel_bias_t0_sigma_ug") if t0 else est.get("accel_bias_sigma_ug")) or [None] * 3
    return [Reading(None if start[k] is None else start[k] - truth[k],
                    f"estimate − truth ({format_value(truth[k])} µg), {a} axis", sigma[k], f"_{a}")
            for k, a in enumerate(AXES)]


def _drift(result: dict) -> list[Reading]:
    drift = _estimate(result).get("accel_bias_drift_ug_per_h")
    if drift is None:
        return []
    sigma = _estimate(result).get("accel_bias_drift_sigma_ug_per_h") or [None] * 3
    return [Reading(drift[k], f"bias drift rate ±{format_value(sigma[k])} (1σ), {a} axis (2018 gravity-vector paper, "
                    "b = b_s + k t)", sigma[k], f"_{a}") for k, a in enumerate(AXES)]


def _drift_check(result: dict) -> list[Reading]:
    check = _estimate(result).get("drift_check")
    return [] if check is None else [Reading(check["significant"], "15-state drift check: some axis drifts beyond 4σ ("
                                             + ", ".join(format_value(v) for v in check["drift_ug_per_h"]) + " µg/h)")]


def _gyros_drift(result: dict) -> list[Reading]:
    gyros = drift_not_the_accelerometer(result)
    if gyros is None:
        return []
    table = result["table_reference"]["accel_bias_drift_ug_per_h"]
    return [Reading(gyros, "a drift the self-calibration sees that the table-referenced fit ("
                    + ", ".join(format_value(v) for v in table)
                    + " µg/h) does not: the gyros' errors turning the attitude, not the accelerometer")]


def _method2(result: dict) -> dict:
    return (result.get("alignment_deg") or {}).get("method2") or {}


def _other_alignments(result: dict) -> list[Reading]:
    """Method 1's pitch, roll and yaw errors and the theoretical pitch and roll errors the trial has."""
    alignment = result.get("alignment_deg") or {}
    out = []
    for method, angles in (("method1", ("pitch", "roll", "yaw")), ("theoretical", ("pitch", "roll"))):
        values = alignment.get(method) or {}
        what = "method-1" if method == "method1" else "theoretical (2019 eq. 8)"
        out += [Reading(values[angle], f"{what} {angle} error", suffix=f"_{method}_{angle}") for angle in angles
                if angle in values]
    return out


def _table_bias(result: dict) -> list[Reading]:
    table = result.get("table_reference") or {}
    if table.get("accel_bias_ug") is None:
        return []
    return _axes(table["accel_bias_ug"], "bias from the turntable attitude", table.get("accel_bias_sigma_ug"))


def _calibration_reading(key: str, description: str, truth_only: bool = False) -> Callable[[dict], list[Reading]]:
    """The reader of the calibration's figure ``key`` (none without a calibration); ``truth_only``: judged on an
    emulated trial alone, whose document holds the truth."""
    def read(result: dict) -> list[Reading]:
        calibration = result.get("calibration")
        if calibration is None:
            return []
        applies = not truth_only or "truth" in result
        return [Reading(calibration[key], description, limit=Limit.JUDGED if applies else Limit.NONE)]

    return read


def _streams(result: dict) -> dict:
    return result.get("streams") or {}


def _fraction(numerator: Callable[[dict], float], description: str) -> Callable[[dict], list[Reading]]:
    """Of the aligned streams' IMU samples (filled, bridged and aligned: a simulation's are not aligned, and have
    none), the fraction ``numerator(streams)``."""
    def read(result: dict) -> list[Reading]:
        streams = _streams(result)
        if "aligner_aligned" not in streams:
            return []
        slots = max(streams["aligner_aligned"] + streams["aligner_imu_bridged"], 1)
        return [Reading(numerator(streams) / slots, description)]

    return read


def _sync_offset(result: dict) -> list[Reading]:
    streams = _streams(result)
    if "aligner_aligned" not in streams:
        return []
    what = "lag of the table's angles behind the IMU, from the gyros against the table's rate"
    offset = streams.get("sync_offset_ms")
    return [Reading(None, f"{what}: no motion to measure it by", limit=Limit.NONE) if offset is None
            else Reading(offset, what)]


def _counters(result: dict) -> list[Reading]:
    """Every other figure of the streams, each named for its counter, in result.json's order."""
    out = []
    for key, value in _streams(result).items():
        if key == "sync" and value:
            out += [Reading(len(v) if isinstance(v, list) else v, "sync pairing", suffix=f"stream_sync_{k}")
                    for k, v in value.items()]
        elif key == "imu_temperature_c":
            out += [Reading(v, f"the IMU's own temperature, {k} over the trial", suffix=f"imu_temperature_{k}",
                            unit="°C") for k, v in (value or {}).items()]
        elif key == "imu_invalid_by_flag":
            out += [Reading(n, "samples the IMU flagged so", suffix=f"imu_invalid_{flag}") for flag, n in value.items()]
        elif key == "gyro_rate_error_dph":
            out += [Reading(v, f"gyro rate minus the table's, {a} axis: the gyro bias, plus scale factor and "
                            "misalignment times the rate of a turning axis", suffix=f"gyro_rate_error_{a}", unit="°/h")
                    for a, v in zip(AXES, value or ())]
        elif key not in ("dropped", "corrupt", "sync"):
            unit = "frames" if "frames" in key else ""
            out.append(Reading(value, "stream counter", suffix=f"stream_{key}", unit=unit))
    return out


CONVERGED = "first solve after which every estimate is settled: 3σ and its distance to each later one within 10 µg"
# every measurement of a trial, in the order the outputs list them
DECLARED = (
    Declared("accel_bias", "µg", lambda r: _axes(_estimate(r).get("accel_bias_ug"),
                                                 "accelerometer bias estimate, {axis} axis",
                                                 _estimate(r).get("accel_bias_sigma_ug"))),
    Declared("accel_bias_sigma", "µg", lambda r: _axes(_estimate(r).get("accel_bias_sigma_ug"),
                                                       "1σ of the bias estimate, {axis} axis"), "bias_sigma_ug_max"),
    Declared("accel_bias_error", "µg", _bias_error, "bias_error_ug_max", absolute=True),
    Declared("bias_observable", "", lambda r: _one(_estimate(r).get("observable"), "scaled Gram matrix of full rank")),
    Declared("gram_rank", "of 12", lambda r: _one(_estimate(r).get("gram_rank"),
                                                  "rank of the scaled Gram matrix (2019 eq. 19)")),
    Declared("gram_condition", "", lambda r: _one(_estimate(r).get("gram_condition"),  # null: a singular matrix
                                                  "condition number of the scaled Gram matrix",
                                                  "gram_condition" in _estimate(r))),
    Declared("converged_at", "s", lambda r: _one(_estimate(r).get("converged_at_s"), CONVERGED), "converged_by_s",
             pending="not converged yet"),
    Declared("accel_bias_drift", "µg/h", _drift),
    Declared("bias_drift_significant", "", _drift_check),
    Declared("bias_drift_not_in_table_reference", "", _gyros_drift),
    Declared("accel_noise", "µg", lambda r: _one(_estimate(r).get("noise_ug"), "residual RMS per axis and sample",
                                                 _estimate(r).get("noise_ug") is not None)),
    Declared("alignment_method2_pitch", "deg", lambda r: _one(_method2(r).get("pitch"), "method-2 pitch error "
             "against the turntable, mean of the last 10 %"), "method2_error_deg_max", absolute=True),
    Declared("alignment_method2_roll", "deg", lambda r: _one(_method2(r).get("roll"), "method-2 roll error "
             "against the turntable, mean of the last 10 %"), "method2_error_deg_max", absolute=True),
    Declared("alignment_method2_yaw", "deg", lambda r: _one(_method2(r).get("yaw"), "method-2 yaw error, mean of the "
                                                            "last 10 %", "yaw" in _method2(r))),
    Declared("alignment", "deg", _other_alignments),
    Declared("table_referenced_bias", "µg", _table_bias),
    Declared("calibration_residual_max", "µg", _calibration_reading("residual_max_ug", "largest specific-force "
             "residual at a position, after calibration (calibration.json)"), "calibration_residual_ug_max"),
    Declared("calibration_error_worst", "σ", _calibration_reading("worst_error_sigma", "largest |estimate − truth| "
             "of an observable term, in its 1σ (emulated trials)", truth_only=True), "calibration_error_sigma_max"),
    Declared("frames_dropped", "frames", lambda r: [Reading(_streams(r).get("dropped"), "frames lost")], "dropped_max"),
    Declared("frames_corrupt", "frames", lambda r: [Reading(_streams(r).get("corrupt"), "frames with a bad checksum "
                                                            "or framing")], "corrupt_max"),
    Declared("imu_missing_fraction", "", _fraction(lambda s: s["aligner_imu_filled"] + s["aligner_imu_bridged"],
             "IMU samples filled or bridged (their frames lost), of all"), "missing_max"),
    Declared("imu_gated_fraction", "", _fraction(lambda s: s["imu_gated"], "IMU samples the gyro/table gate removed, "
                                                 "of all"), "gated_max"),
    Declared("imu_invalid_fraction", "", _fraction(lambda s: s.get("imu_invalid", 0), "IMU samples the IMU's own "
             "status flagged invalid (never estimated), of all"), "invalid_max"),
    Declared("imu_without_angles_fraction", "", _fraction(lambda s: s["aligner_without_angles"], "IMU samples aligned "
             "without table angles, of all"), "without_angles_max"),
    Declared("sync_offset", "ms", _sync_offset, "sync_offset_ms_max", absolute=True),
    Declared("", "", _counters),
)


def measurements(result: dict, limits: ReportLimits) -> list[Measurement]:
    """The trial's measurements from a result.json document, judged against ``limits``: what :data:`DECLARED`
    reads of it, in that order."""
    duration = (result.get("trial") or {}).get("duration_s") or 0.0
    judged = (_judged(declared, reading, limits, duration) for declared in DECLARED
              for reading in declared.read(result))
    return [m for m in judged if m is not None]


def _judged(declared: Declared, reading: Reading, limits: ReportLimits, duration: float) -> Measurement | None:
    """The measurement of one reading; None for a reading whose limit is only shown, when none is set."""
    name, unit = declared.name + reading.suffix, declared.unit if reading.unit is None else reading.unit
    bound = None if declared.limit is None or reading.limit is Limit.NONE else getattr(limits, declared.limit)
    pending = declared.pending and reading.value is None and bound is not None and duration < bound
    if reading.limit is Limit.SHOWN or pending:
        if bound is None:
            return None
        description = (f"{declared.pending} when the trial ended at {format_value(duration)} s, before the limit: "
                       f"{reading.description}" if pending else reading.description)
        return Measurement(name, reading.value, unit, _limit_text(bound, declared.absolute), NOT_JUDGED, description,
                           reading.sigma)
    return _at_most(name, reading.value, unit, bound, reading.description, declared.absolute, reading.sigma)


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
