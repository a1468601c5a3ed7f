"""``imu.calibration``: a calibration.json's inverse model applied to the raw increments, before anything
else of the pipeline sees them (:func:`hil.estimation.calibration_model.compensate`).

The file's ``accel`` and ``gyro`` blocks use the keys, order and signs of ``imu.errors``; a ``null`` term is
not compensated. Its ``turntable.zero_offset_arcsec`` (true gimbal angle minus encoder reading, outer, middle,
inner; optional) is added to the table's reported angles: the IMU's terms were fitted against the corrected
angles, and the table-referenced estimates need them too (the inner offset, unobservable, is folded into the
IMU's misalignment and ``null``). A file that cannot be applied raises :class:`CalibrationFileError` (a
:class:`hil.inputs.ConfigError`) naming the key, the file and the reason, in one line.
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

from hil.inputs import ConfigError
from hil.estimation.calibration_model import BIAS, MIS, NONLIN, SCALE, TERMS, compensate, inverse
from hil.estimation.thermal_calibration import ThermalTerms, compensate_each
from hil.samples import AlignedBatch, ImuSamples, TableSamples
from hil.units import ARCSEC, DEG_PER_H, PPM, UG, UG_PER_G2

# (key, slice of theta, SI per unit)
ACCEL_KEYS = (("bias_ug", BIAS, UG), ("scale_ppm", SCALE, PPM), ("misalignment_arcsec", MIS, ARCSEC),
              ("nonlinearity_ug_per_g2", NONLIN, UG_PER_G2))
GYRO_KEYS = (("bias_dph", BIAS, DEG_PER_H), ("scale_ppm", SCALE, PPM), ("misalignment_arcsec", MIS, ARCSEC))
ZERO_KEY = "zero_offset_arcsec"  # of the file's turntable block


class CalibrationFileError(ConfigError):
    """A calibration file that cannot be applied; the message names the file, the key and the reason."""


class Compensation:
    """The inverse model of one calibration file for increments over ``period`` s."""

    def __init__(self, path: str | Path, period: float) -> None:
        self.path = str(path)
        data, doc = _read(Path(path))
        self.accel, self.gyro = _thetas(Path(path), doc)
        self.zero_offsets = _zero_offsets(Path(path), doc)
        self.thermal = thermal_terms(Path(path), doc)
        self.period = period
        self.applied = {"path": self.path, "sha256": hashlib.sha256(data).hexdigest(), **applied_terms(doc)}

    def _compensated(self, dtheta: np.ndarray, dv: np.ndarray, dt, temperature_c: np.ndarray | None):
        """Compensated increments: with the terms at each sample's temperature when the file has ``thermal``."""
        if self.thermal is None:
            return compensate(self.accel, self.gyro, dtheta, dv, dt)
        temperature = np.full(len(dv), np.nan) if temperature_c is None else temperature_c
        accel, gyro = self.thermal
        return compensate_each(accel.thetas(self.accel, temperature), gyro.thetas(self.gyro, temperature), dtheta,
                               dv, dt)

    def samples(self, samples: ImuSamples) -> ImuSamples:
        """Decoded IMU samples with compensated increments (one vectorised call a chunk)."""
        if not len(samples):
            return samples
        dtheta, dv = self._compensated(samples.dtheta, samples.dv, self.period, samples.temperature_c)
        return dataclasses.replace(samples, dtheta=dtheta, dv=dv)

    def table(self, samples: TableSamples) -> TableSamples:
        """Decoded table samples with the gimbal zero offsets added to their encoder angles."""
        return dataclasses.replace(samples, angles=samples.angles + self.zero_offsets) if len(samples) else samples

    def batch(self, batch: AlignedBatch) -> AlignedBatch:
        """A batch with compensated increments, each over its own interval, and zero-offset angles."""
        dt = np.diff(np.concatenate(([batch.t0], batch.t)))
        dtheta, dv = self._compensated(batch.dtheta, batch.dv, dt, batch.temperature_c)
        angles = None if batch.angles is None else batch.angles + self.zero_offsets
        return dataclasses.replace(batch, dtheta=dtheta, dv=dv, angles=angles)


def load_calibration(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The (accel, gyro) theta vectors (18,) in SI of a calibration.json, for
    :func:`hil.estimation.calibration_model.compensate`; a ``null`` term is not compensated (zero).

    Raises :class:`CalibrationFileError` naming the file, key and reason.
    """
    return _thetas(Path(path), _read(Path(path))[1])


def compensated_bias(accel: np.ndarray, bias: np.ndarray, drift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bias (3,) m/s^2 and drift (3,) m/s^2 per hour of the compensated accelerometer output, for an
    injected bias and drift (the same units) under the applied theta ``accel`` (18,).

    The bias is the compensated output at zero specific force: the sensor then outputs its bias alone (``v = 0``
    in the forward model), so it is :func:`~hil.estimation.calibration_model.inverse` of the injected bias,
    ``K^-1 (b - b_hat)`` to first order with the applied scale, misalignment and nonlinearity. The drift is that
    output's change over an hour of injected drift.
    """
    seen = inverse(accel, np.asarray(bias, dtype=float))[0]
    return seen, inverse(accel, np.asarray(bias, dtype=float) + drift)[0] - seen


def applied_terms(doc: dict) -> dict:
    """``terms``: per block the keys with a value applied; ``null_terms``: ``block.key.index`` of the terms
    left uncompensated (``null``), of a document :func:`load_calibration` accepts; with a ``thermal`` block,
    ``thermal``: its ``reference_c``, ``order`` and the terms applied at each sample's temperature."""
    terms: dict[str, list[str]] = {}
    nulls: list[str] = []
    blocks = [("accel", ACCEL_KEYS, doc["accel"]), ("gyro", GYRO_KEYS, doc["gyro"])]
    if isinstance(doc.get("turntable"), dict) and ZERO_KEY in doc["turntable"]:
        blocks.append(("turntable", ((ZERO_KEY, None, ARCSEC),), doc["turntable"]))
    for block, keys, part in blocks:
        terms[block] = [key for key, _, _ in keys if any(v is not None for v in part[key])]
        nulls += [f"{block}.{key}.{i}" for key, _, _ in keys for i, v in enumerate(part[key]) if v is None]
    thermal = doc.get("thermal")
    extra = {} if not isinstance(thermal, dict) else {"thermal": {
        "reference_c": thermal.get("reference_c"), "order": thermal.get("order"), "terms": sorted(thermal["terms"])}}
    return {"terms": terms, "null_terms": nulls, **extra}


def thermal_terms(path: Path, doc: dict) -> tuple[ThermalTerms, ThermalTerms] | None:
    """The (accel, gyro) :class:`~hil.estimation.thermal_calibration.ThermalTerms` of the file's ``thermal`` block
    (None without one): each ``terms`` entry ``block.key.index`` with ``coefficients`` lowest order first, in the
    key's unit per deg C^j; raises :class:`CalibrationFileError` naming the key."""
    part = doc.get("thermal")
    if part is None:
        return None
    where = f"imu.calibration: {path}: thermal"
    if not isinstance(part, dict) or not isinstance(part.get("terms"), dict):
        raise CalibrationFileError(f"{where}: expected an object with reference_c, order and terms")
    reference = _number(path, "thermal.reference_c", part.get("reference_c", "missing"))
    order = part.get("order")
    if order not in (1, 2, 3):
        raise CalibrationFileError(f"{where}.order: expected 1, 2 or 3, got {order!r}")
    keys = {"accel": {key: (sl, unit) for key, sl, unit in ACCEL_KEYS},
            "gyro": {key: (sl, unit) for key, sl, unit in GYRO_KEYS}}
    slopes = {block: np.zeros((order, len(TERMS))) for block in keys}
    for name, term in part["terms"].items():
        block, key, index = (name.split(".") + ["", "", ""])[:3]
        found = keys.get(block, {}).get(key)
        if found is None or not index.isdigit() or int(index) >= found[0].stop - found[0].start:
            raise CalibrationFileError(f"{where}.terms.{name}: not a term (expected block.key.index, e.g. "
                                       "accel.bias_ug.0)")
        coefficients = term.get("coefficients") if isinstance(term, dict) else None
        if not isinstance(coefficients, list) or len(coefficients) != order + 1:
            raise CalibrationFileError(f"{where}.terms.{name}.coefficients: expected a list of {order + 1} numbers")
        for j, value in enumerate(coefficients[1:], start=1):
            slopes[block][j - 1, found[0].start + int(index)] = _number(
                path, f"thermal.terms.{name}.coefficients[{j}]", value) * found[1]
    return ThermalTerms(reference, slopes["accel"]), ThermalTerms(reference, slopes["gyro"])


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


def _zero_offsets(path: Path, doc: dict) -> np.ndarray:
    """``turntable.zero_offset_arcsec`` in rad (3,), a ``null`` (or a missing block) as zero."""
    part = doc.get("turntable")
    if part is None or ZERO_KEY not in part:
        return np.zeros(3)
    values = part[ZERO_KEY] if isinstance(part, dict) else None
    if not isinstance(values, list) or len(values) != 3:
        raise CalibrationFileError(f"imu.calibration: {path}: turntable.{ZERO_KEY}: expected a list of 3 numbers or nulls")
    return np.array([_number(path, f"turntable.{ZERO_KEY}[{i}]", v) for i, v in enumerate(values)]) * ARCSEC


def _number(path: Path, where: str, value: object) -> float:
    """A term's value (``null``: 0, not compensated); raises :class:`CalibrationFileError` for anything else."""
    if value is None:
        return 0.0
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CalibrationFileError(f"imu.calibration: {path}: {where}: expected a finite number, got {value!r}")
    return float(value)


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
            theta[sl.start + i] = _number(path, f"{block}.{key}[{i}]", v) * unit
    return theta
