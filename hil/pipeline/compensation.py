"""``imu.calibration``: a calibration.json's inverse model applied to the raw increments, before anything
else of the pipeline sees them (:func:`hil.estimation.calibration_model.compensate`).

The file's ``accel`` and ``gyro`` blocks use the keys, order and signs of ``imu.errors``; a ``null`` term is
not compensated. A file that cannot be applied raises :class:`CalibrationFileError` (a
:class:`hil.config.ConfigError`) naming the key, the file and the reason, in one line.
:attr:`Compensation.applied` says which file (path, SHA-256 of the bytes read) and which terms were applied:
result.json's ``calibration_applied``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from hil.config import ConfigError
from hil.estimation.calibration_model import BIAS, MIS, NONLIN, SCALE, TERMS, compensate
from hil.samples import AlignedBatch, ImuSamples
from hil.units import ARCSEC, DEG_PER_H, PPM, UG, UG_PER_G2

# (key, slice of theta, SI per unit)
ACCEL_KEYS = (("bias_ug", BIAS, UG), ("scale_ppm", SCALE, PPM), ("misalignment_arcsec", MIS, ARCSEC),
              ("nonlinearity_ug_per_g2", NONLIN, UG_PER_G2))
GYRO_KEYS = (("bias_dph", BIAS, DEG_PER_H), ("scale_ppm", SCALE, PPM), ("misalignment_arcsec", MIS, ARCSEC))


class CalibrationFileError(ConfigError):
    """A calibration file that cannot be applied; the message names the file, the key and the reason."""


class Compensation:
    """The inverse model of one calibration file for increments over ``period`` s."""

    def __init__(self, path: str | Path, period: float) -> None:
        self.path = str(path)
        data, doc = _read(Path(path))
        self.accel, self.gyro = _thetas(Path(path), doc)
        self.period = period
        self.applied = {"path": self.path, "sha256": hashlib.sha256(data).hexdigest(), **applied_terms(doc)}

    def samples(self, samples: ImuSamples) -> ImuSamples:
        """Decoded IMU samples with compensated increments (one vectorised call a chunk)."""
        if not len(samples):
            return samples
        dtheta, dv = compensate(self.accel, self.gyro, samples.dtheta, samples.dv, self.period)
        return dataclasses.replace(samples, dtheta=dtheta, dv=dv)

    def batch(self, batch: AlignedBatch) -> AlignedBatch:
        """A batch with compensated increments, each over its own interval."""
        dt = np.diff(np.concatenate(([batch.t0], batch.t)))
        dtheta, dv = compensate(self.accel, self.gyro, batch.dtheta, batch.dv, dt)
        return dataclasses.replace(batch, dtheta=dtheta, dv=dv)


def load_calibration(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The (accel, gyro) theta vectors (18,) in SI of a calibration.json, for
    :func:`hil.estimation.calibration_model.compensate`; a ``null`` term is not compensated (zero).

    Raises :class:`CalibrationFileError` naming the file, key and reason.
    """
    return _thetas(Path(path), _read(Path(path))[1])


def applied_terms(doc: dict) -> dict:
    """``terms``: per block the keys with a value applied; ``null_terms``: ``block.key.index`` of the terms
    left uncompensated (``null``), of a document :func:`load_calibration` accepts."""
    terms: dict[str, list[str]] = {}
    nulls: list[str] = []
    for block, keys in (("accel", ACCEL_KEYS), ("gyro", GYRO_KEYS)):
        terms[block] = [key for key, _, _ in keys if any(v is not None for v in doc[block][key])]
        nulls += [f"{block}.{key}.{i}" for key, _, _ in keys for i, v in enumerate(doc[block][key]) if v is None]
    return {"terms": terms, "null_terms": nulls}


def _read(path: Path) -> tuple[bytes, dict]:
    """The file's bytes and its JSON object."""
    try:
        data = path.read_bytes()
        doc = json.loads(data)
    except OSError as exc:
        raise CalibrationFileError(f"imu.calibration: {path}: cannot read: {exc.strerror or exc}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibrationFileError(f"imu.calibration: {path}: not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise CalibrationFileError(f"imu.calibration: {path}: expected a JSON object at the top level")
    return data, doc


def _thetas(path: Path, doc: dict) -> tuple[np.ndarray, np.ndarray]:
    return tuple(_theta(path, doc, block, keys) for block, keys in (("accel", ACCEL_KEYS), ("gyro", GYRO_KEYS)))


def _theta(path: Path, doc: dict, block: str, keys: tuple) -> np.ndarray:
    part = doc.get(block)
    if not isinstance(part, dict):
        raise CalibrationFileError(f"imu.calibration: {path}: {block}: required block is missing")
    expected = {key for key, _, _ in keys}
    extra = sorted(set(part) - expected)
    if extra:
        raise CalibrationFileError(f"imu.calibration: {path}: {block}.{extra[0]}: unknown key (expected {', '.join(sorted(expected))})")
    theta = np.zeros(len(TERMS))
    for key, sl, unit in keys:
        values = part.get(key)
        n = sl.stop - sl.start
        if not isinstance(values, list) or len(values) != n:
            got = f"{len(values)}" if isinstance(values, list) else type(values).__name__
            raise CalibrationFileError(f"imu.calibration: {path}: {block}.{key}: expected a list of {n} numbers or nulls, got {got}")
        for i, v in enumerate(values):
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise CalibrationFileError(f"imu.calibration: {path}: {block}.{key}[{i}]: expected a finite number, got {v!r}")
            theta[sl.start + i] = v * unit
    return theta
