"""A physical plausibility check on decoded IMU samples, behind the wire checksum.

A short checksum (Xsens MTData2's 8 bits) lets a few damaged frames through; when the damage hits a
high bit of a float the sample is wildly wrong. On a turntable the body rate cannot exceed the
table's rate limits by much and the specific force stays within a fraction of g of gravity, so a
sample outside ``max_rate`` or ``|f| - g`` beyond ``force_tolerance`` is rejected (and counted).
Damage to low bits of the increments is caught by comparing the gyro with the table (:class:`GyroTableGate`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.frames import Earth, TableGeometry, table_body_rotation
from hil.units import DEG, G0

RATE_MARGIN = 2.0  # times the fastest configured gimbal rate limit
STALL_S = 5.0  # every IMU sample rejected for this long (of samples) ends a live trial
FORCE_TOLERANCE_G = 0.2
GATE_FLOOR_RAD = 1e-5  # gyro/table disagreement allowed per sample, plus ...
GATE_FRACTION = 0.01  # ... this fraction of the sample's rotation


class ImuPlausibility:
    """``ok(dtheta, dv)`` for the samples (N, 3) of a read at ``rate_hz``; ``rejected`` counts the failures."""

    def __init__(self, rate_hz: float, gravity: float, max_rate: float,
                 force_tolerance: float | None = None) -> None:
        self.period = 1.0 / rate_hz
        self.gravity = gravity
        self.max_angle = max_rate * self.period  # rad per sample
        self.force_tolerance = FORCE_TOLERANCE_G * gravity if force_tolerance is None else force_tolerance
        self.rejected = 0
        self.last_rejected: tuple[float, float] | None = None  # (|f| in g, rate / max rate) of the last failure

    def ok(self, dtheta: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """Per sample (N,), True where it is plausible."""
        angle = np.sqrt(np.einsum("ij,ij->i", dtheta, dtheta))
        force = np.sqrt(np.einsum("ij,ij->i", dv, dv)) / self.period
        good = (angle <= self.max_angle) & (np.abs(force - self.gravity) <= self.force_tolerance)
        if not good.all():
            self.rejected += len(good) - int(good.sum())
            last = np.flatnonzero(~good)[-1]
            self.last_rejected = (float(force[last]) / self.gravity, float(angle[last]) / self.max_angle)
        return good

    def diagnosis(self, keys: UnitKeys) -> str:
        """What the last rejected samples say about the config, naming the key most likely wrong (a
        reading in m/s^2 taken as g, or the reverse, is off by G0)."""
        force_g, rate = self.last_rejected or (math.nan, math.nan)
        if any(abs(force_g - r) < 0.05 * r for r in (G0, 1.0 / G0)):
            return (f"the specific force reads {force_g:.3g} g at rest or swinging: the accelerometer unit is "
                    f"wrong (check {keys.accel_unit}: g or m/s^2)")
        if rate > 1.0:
            return (f"the gyros read {rate:.3g} times the table's fastest rate limit: check the gyro unit and output "
                    f"({keys.gyro_unit}, {keys.gyro_output}), imu.rate_hz and turntable.limits")
        return (f"the specific force reads {force_g:.3g} g, not 1 g: check imu.rate_hz (the increments are per "
                f"sample), imu.protocol and {keys.accel_unit}")


@dataclass(frozen=True)
class UnitKeys:
    """The config keys that set the IMU's output units (its codec's :meth:`~drivers.codec.Codec.unit_advice`)."""

    accel_unit: str
    gyro_unit: str
    gyro_output: str


def small_rotation_vectors(c: np.ndarray) -> np.ndarray:
    """Rotation vectors of (N, 3, 3) rotations under 90 deg: ``v asin|v| / |v|`` with ``v`` the axial
    part of ``(C - C^T) / 2`` (|v| = sin of the angle)."""
    v = 0.5 * np.stack((c[:, 2, 1] - c[:, 1, 2], c[:, 0, 2] - c[:, 2, 0], c[:, 1, 0] - c[:, 0, 1]), axis=-1)
    s = np.linalg.norm(v, axis=1)
    scale = np.where(s > 1e-12, np.arcsin(np.minimum(s, 1.0)) / np.maximum(s, 1e-300), 1.0)
    return v * scale[:, None]


class GyroTableGate:
    """Rejects gyro increments that disagree with the rotation the table angles show over the same interval.

    The predicted increment is the rotation vector of ``C_n^b(t1) C_n(t2)^n(t1) C_b^n(t2)`` (gimbal
    angles at both ends plus the earth's turn). Mounting error, scale factor, quantisation and the
    neglected coning term stay far below ``floor + fraction * |rotation|``; a frame whose damage the
    checksum missed does not. Rejected samples become gaps the estimator bridges with the table.
    """

    def __init__(self, earth: Earth, geometry: TableGeometry, floor: float = GATE_FLOOR_RAD,
                 fraction: float = GATE_FRACTION) -> None:
        self.earth = earth
        self.geometry = geometry
        self.floor = floor
        self.fraction = fraction
        self.rejected = 0
        self.last_ratio = math.nan  # |gyro| / |table rotation| (medians) of the last block with a rejection

    def consistent(self, t_start: np.ndarray, t_end: np.ndarray, angles_start: np.ndarray, angles_end: np.ndarray,
                   dtheta: np.ndarray) -> np.ndarray:
        """Per sample (N,), True where the gyro increment agrees with the table."""
        n = len(dtheta)
        relative = table_body_rotation(self.geometry, self.earth, t_end - t_start, angles_start, angles_end)
        predicted = small_rotation_vectors(relative)
        error = np.linalg.norm(dtheta - predicted, axis=1)
        size = np.linalg.norm(predicted, axis=1)
        good = error <= self.floor + self.fraction * size
        self.rejected += int(n - good.sum())
        if not good.all():
            self.last_ratio = float(np.median(np.linalg.norm(dtheta, axis=1)) / max(np.median(size), 1e-300))
        return good

    def diagnosis(self, keys: UnitKeys) -> str:
        """What the disagreement says about the config, naming the key most likely wrong."""
        ratio = self.last_ratio
        if any(abs(ratio - r) < 0.05 * r for r in (1.0 / DEG, DEG)):
            return (f"the gyro increments are {ratio:.3g} times the table's rotation: the gyro unit is wrong "
                    f"(check {keys.gyro_unit}: rad or deg)")
        return (f"the gyro increments are {ratio:.3g} times the rotation the table angles show: check imu.rate_hz "
                f"and trial.rate_hz (which pulse latches the table), the gyro output ({keys.gyro_output}) and "
                f"turntable.mounting_deg")


class RejectionWatch:
    """Counts the IMU samples rejected in a row (none reached the estimator since); :attr:`stalled` once
    they span ``STALL_S`` at the IMU rate, so a live trial with a wrong unit, rate or protocol stops
    within seconds instead of acquiring for ever."""

    def __init__(self, rate_hz: float) -> None:
        self.limit = max(1, round(STALL_S * rate_hz))
        self.run = 0

    def rejected(self, n: int = 1) -> None:
        self.run += n

    def taken(self, rejected_after: int = 0) -> None:
        """Samples reached the estimator; ``rejected_after`` were rejected after the last of them."""
        self.run = rejected_after

    @property
    def stalled(self) -> bool:
        return self.run >= self.limit
