"""``OUT/calibration.json``: the calibration document of DESIGN.md, and reading one back for ``imu.calibration``.

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
from hil.estimation.calibration_model import (
    BIAS,
    INDEX,
    MIS,
    NONLIN,
    SCALE,
    TERMS,
    ZERO,
    Fit,
    Window,
)
from hil.units import ARCSEC, DEG, DEG_PER_H, G0, PPM, UG

UG_PER_G2 = UG / G0**2  # 1/(m/s^2) per ug/g^2
# (key, slice of theta, SI per unit)
ACCEL_KEYS = (("bias_ug", BIAS, UG), ("scale_ppm", SCALE, PPM), ("misalignment_arcsec", MIS, ARCSEC),
              ("nonlinearity_ug_per_g2", NONLIN, UG_PER_G2))
GYRO_KEYS = (("bias_dph", BIAS, DEG_PER_H), ("scale_ppm", SCALE, PPM), ("misalignment_arcsec", MIS, ARCSEC))
NOT_FITTED = "not fitted (left out of calibration.accel_terms / gyro_terms)"


class CalibrationFileError(ValueError):
    """A calibration file that cannot be applied; the message names the file, the key and the reason."""


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
            doc[block][key] = _values(fit, fit.theta, names, unit, f"{block}.{key}", unobservable)
            sigma[block][key] = _values(fit, fit.sigma, names, unit, None, unobservable)
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


def _values(fit: Fit, values: np.ndarray, names: tuple[str, ...], unit: float, key: str | None,
            unobservable: dict[str, str]) -> list[float | None]:
    out: list[float | None] = []
    for i, name in enumerate(names):
        reason = fit.unobservable.get(name) or (None if name in fit.fitted else NOT_FITTED)
        if reason is not None and key is not None:
            unobservable[f"{key}.{i}"] = reason
        out.append(None if reason is not None else float(values[INDEX[name]] / unit))
    return out


def _zero_offset(axis: int, accel: Fit, gyro: Fit | None, unobservable: dict[str, str]) -> tuple:
    """(value, sigma) in arcsec of one gimbal's zero offset: from the accelerometers, else from the gyros."""
    name = TERMS[ZERO][axis]
    reasons = []
    for label, fit in (("accelerometers", accel), ("gyros", gyro)):
        if fit is None:
            continue
        reason = fit.unobservable.get(name) or (None if name in fit.fitted else NOT_FITTED)
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


def load_calibration(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The (accel, gyro) theta vectors (18,) in SI of a calibration.json, for
    :func:`hil.estimation.calibration_model.compensate`; a ``null`` term is not compensated (zero).

    Raises :class:`CalibrationFileError` naming the file, key and reason.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CalibrationFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise CalibrationFileError(f"{path}: not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise CalibrationFileError(f"{path}: expected a JSON object at the top level")
    return tuple(_theta(path, doc, block, keys) for block, keys in (("accel", ACCEL_KEYS), ("gyro", GYRO_KEYS)))


def _theta(path: Path, doc: dict, block: str, keys: tuple) -> np.ndarray:
    part = doc.get(block)
    if not isinstance(part, dict):
        raise CalibrationFileError(f"{path}: {block}: required block is missing")
    expected = {key for key, _, _ in keys}
    extra = sorted(set(part) - expected)
    if extra:
        raise CalibrationFileError(f"{path}: {block}.{extra[0]}: unknown key (expected {', '.join(sorted(expected))})")
    theta = np.zeros(len(TERMS))
    for key, sl, unit in keys:
        values = part.get(key)
        n = sl.stop - sl.start
        if not isinstance(values, list) or len(values) != n:
            got = f"{len(values)}" if isinstance(values, list) else type(values).__name__
            raise CalibrationFileError(f"{path}: {block}.{key}: expected a list of {n} numbers or nulls, got {got}")
        for i, v in enumerate(values):
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise CalibrationFileError(f"{path}: {block}.{key}[{i}]: expected a finite number, got {v!r}")
            theta[sl.start + i] = v * unit
    return theta
