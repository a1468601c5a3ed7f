"""A trial's history row: its record (result.json's ``record``) and the headline figures of its kind, read
from the documents it wrote (docs/history.md, "What a row holds")."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hil.vocabulary import TrialKind

SWING, CALIBRATION, NOISE = TrialKind.SWING, TrialKind.CALIBRATION, TrialKind.NOISE
RECORD_KEYS = ("dut_part", "dut_serial", "station", "operator", "notes", "software_version", "started_utc",
               "ended_utc", "host", "config_sha256")


def swing_figures(result: dict) -> dict[str, Any]:
    """The estimate's bias, its sigma, whether it was observable and when it converged, and the drift check of a
    result.json (ug, ug/h, s)."""
    estimate = result.get("estimate") or {}
    drift = estimate.get("drift_check") or {}
    return {"accel_bias_ug": estimate.get("accel_bias_ug"), "accel_bias_sigma_ug": estimate.get("accel_bias_sigma_ug"),
            "drift_ug_per_h": drift.get("drift_ug_per_h"), "drift_sigma_ug_per_h": drift.get("sigma_ug_per_h"),
            "observable": estimate.get("observable"), "converged_at_s": estimate.get("converged_at_s")}


def calibration_figures(calibration: dict) -> dict[str, Any]:
    """Every term of a calibration.json, keyed ``block.key`` (its units in the key), with its sigma."""
    figures: dict[str, Any] = {}
    for block in ("accel", "gyro"):
        for key, value in (calibration.get(block) or {}).items():
            figures[f"{block}.{key}"] = value
            figures[f"{block}.{key}.sigma"] = (calibration.get("sigma") or {}).get(block, {}).get(key)
    figures["turntable.zero_offset_arcsec"] = (calibration.get("turntable") or {}).get("zero_offset_arcsec")
    return figures


def noise_figures(noise: dict) -> dict[str, Any]:
    """The Allan terms of a noise.json, keyed ``sensor.term`` (its units in the key)."""
    return {f"{sensor}.{key}": value for sensor in ("gyro", "accel") for key, value in (noise.get(sensor) or {}).items()}


def trial_row(kind: str, out: Path, result: dict, verdict: str | None, figures: dict[str, Any],
              replay_of: Path | None = None) -> dict[str, Any]:
    """The row of a trial of ``kind`` written to ``out``: its record, how it ended, its verdict and ``figures``;
    a replay's names the run directory of the trial it re-processed (``replay_of``)."""
    record = result.get("record") or {}
    return {"kind": kind, "name": (result.get("trial") or {}).get("name"), "ended": result.get("ended"),
            "verdict": verdict, "out_dir": str(out.resolve()), "git_commit": record.get("commit"),
            **{key: record.get(key) for key in RECORD_KEYS}, "figures": figures,
            "replay_of": None if replay_of is None else str(replay_of.resolve())}


FIGURES = {SWING: swing_figures, CALIBRATION: calibration_figures, NOISE: noise_figures}  # the figures of each kind


def outcome_row(out: Path, result: dict, verdict: str | None, kind: str, document: dict,
                replay_of: Path | None) -> dict[str, Any]:
    """The row of a trial command's outcome, filed as ``kind`` with the figures of that kind read from
    ``document`` (:meth:`hil.trial.outcome.TrialOutcome.filed_as`)."""
    return trial_row(kind, out, result, verdict, FIGURES[kind](document), replay_of)
