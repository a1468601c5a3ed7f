"""result.json (schema: docs/contracts.md, "result.json"): the document of a trial, its console summary, and the file."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.estimation.apparent_gravity import DriftCheck
from hil.estimation.online import OnlineEstimator, Snapshot
from hil.outputs.conversions import to_ug, to_ug_per_h
from hil.outputs.measurements import FAIL, drift_not_the_accelerometer
from hil.samples import StreamCounts
from hil.units import DEG, UG

RESULT_NAME = "result.json"
COMPLETED = "completed"  # result.json "ended" of a trial that ran its course
INTERRUPTED, ENDED_EARLY = "INTERRUPTED", "ENDED EARLY"  # the verdicts of a trial that did not complete
# the figures of an observable estimate, every one finite in a completed trial
ESTIMATE_FIGURES = ("accel_bias_ug", "accel_bias_sigma_ug", "accel_bias_t0_ug", "accel_bias_t0_sigma_ug",
                    "accel_bias_drift_ug_per_h", "accel_bias_drift_sigma_ug_per_h", "noise_ug")


@dataclass(frozen=True)
class TrialEnd:
    """How a trial ended: ``completed``, ``early`` (``reason``: why) or ``interrupted`` (``reason``: the
    signal). ``str()`` is result.json's ``ended`` (docs/contracts.md), the one place it is written."""

    kind: str
    reason: str = ""

    @classmethod
    def early(cls, reason: object) -> TrialEnd:
        return cls("early", str(reason))

    @classmethod
    def interrupted(cls, signal: str) -> TrialEnd:
        return cls("interrupted", signal)

    def __str__(self) -> str:
        return self.kind if self.kind == COMPLETED else f"{self.kind}: {self.reason}"


def trial_verdict(ended: str, judged: str) -> str:
    """The verdict a lab signs: ``judged`` (PASS or FAIL against ``output.limits``) for a completed trial, else
    how it ended (INTERRUPTED, ENDED EARLY): a trial that did not complete is neither PASS nor FAIL."""
    if ended == COMPLETED:
        return judged
    return INTERRUPTED if ended.startswith("interrupted") else ENDED_EARLY


def verdict_exit_code(verdict: str | None) -> int:
    """The exit code of a trial of ``verdict`` (docs/contracts.md, "Exit codes"): 1 one that did not complete,
    3 a FAIL, 0 a PASS (or no verdict: a noise characterisation)."""
    return {INTERRUPTED: 1, ENDED_EARLY: 1, FAIL: 3}.get(verdict, 0)


def non_finite_figure(result: dict) -> str | None:
    """The first figure of an observable estimate (``estimate.KEY``) that holds NaN or infinity; None when
    every one is finite (an unobservable estimate has none to hold)."""
    estimate = result.get("estimate") or {}
    if not estimate.get("observable"):
        return None
    for key in ESTIMATE_FIGURES:
        if estimate.get(key) is not None and not np.all(np.isfinite(np.asarray(estimate[key], dtype=float))):
            return f"estimate.{key}"
    return None


def _angles(v: np.ndarray | None, names=("pitch", "roll", "yaw")) -> dict[str, float] | None:
    return None if v is None else {n: float(x) / DEG for n, x in zip(names, v)}


def _tail_mean(snapshots: list[Snapshot], attr: str, duration: float) -> np.ndarray | None:
    """Mean of a snapshot error over the last 10 % of the trial."""
    rows = [getattr(s, attr) for s in snapshots if s.t >= 0.9 * duration and getattr(s, attr) is not None]
    return np.mean(rows, axis=0) if rows else None


def _drift_check(check: DriftCheck | None) -> dict | None:
    if check is None:
        return None
    return {"drift_ug_per_h": to_ug_per_h(check.drift), "sigma_ug_per_h": to_ug_per_h(check.sigma),
            "significant": check.significant}


def build_result(name: str, estimator: OnlineEstimator, streams: StreamCounts, truth: dict | None = None) -> dict:
    """The result.json document of a trial; ``truth`` the emulator's injected errors, for comparison."""
    final = estimator.solution()
    snapshots = estimator.snapshots
    duration = final.t
    table = estimator.table_referenced()
    result = {
        "trial": {"name": name, "duration_s": duration, "samples": final.samples},
        "streams": streams.as_dict(),
        "estimate": {
            "bias_model": estimator.bias_model,
            "accel_bias_ug": to_ug(final.full.bias),
            "accel_bias_sigma_ug": to_ug(final.full.bias_sigma),
            **({"accel_bias_t0_ug": to_ug(final.full.bias_t0), "accel_bias_t0_sigma_ug": to_ug(final.full.bias_t0_sigma),
                "accel_bias_drift_ug_per_h": to_ug_per_h(final.full.drift),
                "accel_bias_drift_sigma_ug_per_h": to_ug_per_h(final.full.drift_sigma),
                "drift_converged_at_s": estimator.drift_converged_at()} if estimator.bias_model == "drift" else {}),
            "observable": final.full.observable,
            "gram_rank": final.full.observability.rank,
            "gram_condition": final.full.observability.condition,
            "converged_at_s": estimator.bias_converged_at(),
            "noise_ug": final.full.noise_sigma / UG,
            "drift_check": _drift_check(final.drift_check),
        },
        "table_reference": {
            "accel_bias_ug": to_ug(table.bias),
            "accel_bias_sigma_ug": to_ug(table.bias_sigma),
            "tilt_deg": None if table.tilt is None else [float(x) / DEG for x in table.tilt],
            "accel_bias_drift_ug_per_h": to_ug_per_h(table.drift),
            "accel_bias_drift_sigma_ug_per_h": to_ug_per_h(table.drift_sigma),
        },
        "alignment_deg": {
            "method1": _angles(_tail_mean(snapshots, "error_method1", duration)),
            "method2": _angles(_tail_mean(snapshots, "error_method2", duration)),
            "theoretical": _angles(_tail_mean(snapshots, "error_theoretical", duration), ("pitch", "roll")),
        },
    }
    if truth is not None:
        result["truth"] = dict(truth)
    return result


def trial_result(name: str, estimator: OnlineEstimator | None, streams: StreamCounts, truth: dict | None = None,
                 bias_model: str = "constant") -> dict:
    """The result.json document of a trial; estimates null when no IMU sample reached the estimator."""
    if estimator is None:
        return empty_result(name, streams, truth, bias_model)
    return build_result(name, estimator, streams, truth)


def empty_result(name: str, streams: StreamCounts, truth: dict | None = None, bias_model: str = "constant") -> dict:
    """The result.json document of a trial in which no IMU sample reached the estimator."""
    result = {
        "trial": {"name": name, "duration_s": 0.0, "samples": 0},
        "streams": streams.as_dict(),
        "estimate": {"bias_model": bias_model, "accel_bias_ug": None, "accel_bias_sigma_ug": None, "observable": False,
                     "gram_rank": 0, "gram_condition": None, "converged_at_s": None, "noise_ug": None,
                     "drift_check": None},
        "table_reference": {"accel_bias_ug": None, "accel_bias_sigma_ug": None, "tilt_deg": None,
                            "accel_bias_drift_ug_per_h": None, "accel_bias_drift_sigma_ug_per_h": None},
        "alignment_deg": {"method1": None, "method2": None, "theoretical": None},
    }
    if truth is not None:
        result["truth"] = dict(truth)
    return result


def strict_json(value: Any) -> Any:
    """``value`` with every non-finite float (at any depth) replaced by None: JSON has no NaN or Infinity."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    return value


def write_result(out: Path, result: dict) -> None:
    """``out/result.json``, strict JSON: null for a non-finite number."""
    (out / RESULT_NAME).write_text(json.dumps(strict_json(result), indent=2, allow_nan=False) + "\n")


def summary_text(result: dict, out: Path) -> str:
    """The console summary of a result.json document: the calibration of a ``hil calibrate`` trial, the
    swing estimator's results otherwise."""
    lines = [f"{result['trial']['name']}: {result['trial']['samples']} samples, {result['trial']['duration_s']:.1f} s"]
    lines += _calibration_lines(result["calibration"], out) if "calibration" in result else _estimate_lines(result)
    if result.get("calibration_applied"):
        lines.append(f"  {calibration_applied_text(result['calibration_applied'])}")
    lines.append(f"  outputs in {out}")
    return "\n".join(lines)


def _calibration_lines(calibration: dict, out: Path) -> list[str]:
    lines = [f"  calibration over {calibration['positions']} positions: residual "
             + ("n/a" if calibration["residual_rms_ug"] is None else
                f"{calibration['residual_rms_ug']:.2f} ug RMS, {calibration['residual_max_ug']:.2f} ug max")]
    if calibration["worst_error_sigma"] is not None:
        lines.append(f"  largest error of a term against the emulated truth: {calibration['worst_error_sigma']:.2f} sigma")
    if calibration["unobservable"]:
        lines.append("  unobservable: " + ", ".join(calibration["unobservable"]))
    lines.append(f"  terms and sigmas: {out / calibration['file']}")
    return lines


def _estimate_lines(result: dict) -> list[str]:
    est = result["estimate"]
    lines = []
    if est["observable"]:
        bias = ", ".join(f"{b:.3f} +- {s:.3f}" for b, s in zip(est["accel_bias_ug"], est["accel_bias_sigma_ug"]))
        lines.append(f"  accelerometer bias (ug): {bias}")
        converged = "not converged" if est["converged_at_s"] is None else f"converged at {est['converged_at_s']:.0f} s"
        lines.append(f"  {converged}, Gram rank {est['gram_rank']}")
        if est.get("accel_bias_drift_ug_per_h"):
            drift = ", ".join(f"{k:.3f} +- {s:.3f}" for k, s in zip(est["accel_bias_drift_ug_per_h"],
                                                                    est["accel_bias_drift_sigma_ug_per_h"]))
            lines.append(f"  bias drift (ug/h): {drift}")
    else:
        lines.append(f"  accelerometer bias NOT observable (Gram rank {est['gram_rank']} of 12): the table must swing")
    check = est.get("drift_check")
    if drift_not_the_accelerometer(result):
        reference = result["table_reference"]
        lines.append("  WARNING: the bias seems to drift (" + ", ".join(f"{k:.2f}" for k in check["drift_ug_per_h"])
                     + " ug/h), the table-referenced bias does not drift so (" + ", ".join(
                         f"{k:.3f} +- {s:.3f}" for k, s in zip(reference["accel_bias_drift_ug_per_h"],
                                                              reference["accel_bias_drift_sigma_ug_per_h"])) + " ug/h):")
        lines.append("    the gyros' errors turn the attitude over the trial, not the accelerometer; the"
                     " self-calibrated bias may be off by more than its sigma (the model takes the gyros as perfect)")
    elif check and check["significant"] and est.get("bias_model") != "drift":
        lines.append("  WARNING: the bias drifts (" + ", ".join(f"{k:.2f}" for k in check["drift_ug_per_h"])
                     + " ug/h, beyond 4 sigma): set estimator.bias_model: drift")
    table = result["table_reference"]["accel_bias_ug"]
    if table is not None:
        lines.append("  table-referenced bias (ug): " + ", ".join(f"{b:.3f}" for b in table))
    if "truth" in result:
        lines.append("  truth (ug): " + ", ".join(f"{b:.3f}" for b in result["truth"]["accel_bias_ug"]))
    m2 = result["alignment_deg"]["method2"]
    if m2:
        lines.append(f"  method-2 alignment error (deg): pitch {m2['pitch']:.2e}, roll {m2['roll']:.2e}")
    return lines + _gyro_lines(result["streams"])


def _gyro_lines(streams: dict) -> list[str]:
    """What the trial says of the gyros: their rate against the table's, where the table moved."""
    error = streams.get("gyro_rate_error_dph")
    if error is None:
        return []
    return ["  gyro rate minus the table's (deg/h): " + ", ".join(f"{e:.3g}" for e in error),
            "    the gyro bias, plus scale factor and misalignment times the rate of a turning axis (not separated)"]


def calibration_applied_text(applied: dict | None) -> str:
    """One line: which calibration file (and its digest) and which terms were applied to the increments."""
    if not applied:
        return "no calibration applied (imu.calibration not set)"
    blocks = "; ".join(f"{block} " + (", ".join(k.split("_")[0] for k in keys) or "none")
                       for block, keys in applied["terms"].items())
    nulls = f", {len(applied['null_terms'])} null terms not applied" if applied["null_terms"] else ""
    return f"calibration applied: {applied['path']} (sha256 {applied['sha256'][:12]}): {blocks}{nulls}"
