"""``OUT/calibration.json``: the calibration document (docs/contracts.md, "calibration.json"), read back for ``imu.calibration`` by :mod:`hil.pipeline.compensation`.

The ``accel`` and ``gyro`` blocks use the keys, order and signs of ``imu.errors``; a term the schedule
could not observe, or that was not fitted, is ``null`` with its reason under ``"unobservable"`` keyed
as ``block.key.index`` (``turntable.zero_offset_arcsec.2``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from hil.config import ImuErrors
from hil.estimation.accel_calibration import AccelCalibration
from hil.estimation.calibration_fit import Fit
from hil.estimation.calibration_model import (
    INDEX,
    TERMS,
    ZERO,
    Window,
)
from hil.pipeline.compensation import ACCEL_KEYS, GYRO_KEYS
from hil.units import ARCSEC, DEG, UG

HELD_BY_GYROS = ("taken from the accelerometers: the gyro fit holds the middle and inner zero offsets at their "
                 "values")


def calibration_document(accel: AccelCalibration, gyro: Fit | None, windows: list[Window],
                         truth: ImuErrors | None = None,
                         truth_zero_offset_arcsec: tuple[float, float, float] | None = None) -> dict:
    """The calibration.json mapping from the accelerometer stages, the gyro fit and the dwell windows (in
    the order given to the accelerometer calibration); ``truth`` for emulated trials."""
    unobservable: dict[str, str] = {}
    fits = [("accel", accel.refined, ACCEL_KEYS)] + ([("gyro", gyro, GYRO_KEYS)] if gyro is not None else [])
    doc: dict = {}
    sigma: dict = {}
    for block, fit, keys in fits:
        doc[block], sigma[block] = {}, {}
        for key, part, unit in keys:
            names = TERMS[part]
            doc[block][key] = _values(fit, block, fit.theta, names, unit, f"{block}.{key}", unobservable)
            sigma[block][key] = _values(fit, block, fit.sigma, names, unit, None, unobservable)
    doc["sigma"] = sigma
    zero = [_zero_offset(k, accel.refined, gyro, unobservable) for k in range(3)]
    doc["turntable"] = {"zero_offset_arcsec": [z[0] for z in zero], "zero_offset_sigma_arcsec": [z[1] for z in zero]}
    static = [w for w in windows if w.static]
    doc["positions"] = [
        {"angles_deg": [float(a) for a in np.mean(w.angles, axis=0) / DEG], "dwell_s": w.duration_s,
         "samples": w.samples, "residual_ug": [float(r) for r in residual / UG]}
        for w, residual in zip(static, accel.refined.residuals, strict=True)
    ]
    doc["unobservable"] = unobservable
    if truth is not None:
        doc["truth"] = {
            "accel": {"bias_ug": list(truth.accel_bias_ug), "scale_ppm": list(truth.accel_scale_ppm),
                      "misalignment_arcsec": list(truth.accel_misalignment_arcsec),
                      "nonlinearity_ug_per_g2": list(truth.accel_nonlinearity_ug_per_g2)},
            "gyro": {"bias_dph": list(truth.gyro_bias_dph), "scale_ppm": list(truth.gyro_scale_ppm),
                     "misalignment_arcsec": list(truth.gyro_misalignment_arcsec)},
        }
        if truth_zero_offset_arcsec is not None:
            doc["truth"]["turntable"] = {"zero_offset_arcsec": list(truth_zero_offset_arcsec)}
    return doc


def _not_fitted(block: str) -> str:
    """The reason of a term its block's ``calibration.accel_terms`` / ``gyro_terms`` leaves out."""
    return f"not fitted (left out of calibration.{block}_terms)"


def _reason(fit: Fit, block: str, name: str) -> str | None:
    """Why the fit gives no value for ``name``: unobservable (the fit's reason) or not fitted; None when it does."""
    return fit.unobservable.get(name) or (None if name in fit.fitted else _not_fitted(block))


def _values(fit: Fit, block: str, values: np.ndarray, names: tuple[str, ...], unit: float, key: str | None,
            unobservable: dict[str, str]) -> list[float | None]:
    out: list[float | None] = []
    for i, name in enumerate(names):
        reason = _reason(fit, block, name)
        if reason is not None and key is not None:
            unobservable[f"{key}.{i}"] = reason
        out.append(None if reason is not None else float(values[INDEX[name]] / unit))
    return out


def _zero_offset(axis: int, accel: Fit, gyro: Fit | None, unobservable: dict[str, str]) -> tuple:
    """(value, sigma) in arcsec of one gimbal's zero offset: from the accelerometers, else from the gyros (which
    fit the outer one only)."""
    name = TERMS[ZERO][axis]
    reasons = []
    for block, label, fit in (("accel", "accelerometers", accel), ("gyro", "gyros", gyro)):
        if fit is None:
            continue
        reason = HELD_BY_GYROS if block == "gyro" and axis > 0 else _reason(fit, block, name)
        if reason is None:
            k = INDEX[name]
            return float(fit.theta[k] / ARCSEC), float(fit.sigma[k] / ARCSEC)
        reasons.append(f"{label}: {reason}")
    unobservable[f"turntable.zero_offset_arcsec.{axis}"] = "; ".join(reasons)
    return None, None


def write_calibration(path: str | Path, document: dict) -> None:
    """Write the document as JSON (NaN sigmas, e.g. without degrees of freedom, as null)."""
    Path(path).write_text(json.dumps(_nan_to_null(document), indent=2) + "\n", encoding="utf-8")


def _nan_to_null(value):
    if isinstance(value, dict):
        return {k: _nan_to_null(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_nan_to_null(v) for v in value]
    return None if isinstance(value, float) and not math.isfinite(value) else value
