"""``imu.calibration``: a calibration.json's inverse model applied to the raw increments, before anything
else of the pipeline sees them (:func:`hil.estimation.calibration_model.compensate`).

The file's ``accel`` and ``gyro`` blocks use the keys, order and signs of ``imu.errors``; a ``null`` term is
not compensated. A file that cannot be applied raises :class:`CalibrationFileError` (a
:class:`hil.config.ConfigError`) naming the key, the file and the reason, in one line.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from hil.config import ConfigError
from hil.estimation.calibration_model import BIAS, MIS, NONLIN, SCALE, TERMS, compensate
from hil.samples import AlignedBatch, ImuSamples
from hil.units import ARCSEC, DEG_PER_H, G0, PPM, UG

UG_PER_G2 = UG / G0**2  # 1/(m/s^2) per ug/g^2
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
        self.accel, self.gyro = load_calibration(path)
        self.period = period

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
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CalibrationFileError(f"imu.calibration: {path}: cannot read: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise CalibrationFileError(f"imu.calibration: {path}: not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise CalibrationFileError(f"imu.calibration: {path}: expected a JSON object at the top level")
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
