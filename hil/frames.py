"""Earth model, frames and turntable kinematics.

Frames: n is East-North-Up, b is Right-Forward-Up, n0 is n frozen in inertial space at the trial
start. Attitude angles follow the turntable's gimbal order: ``C_b^n = Rz(yaw) Rx(pitch) Ry(roll)``,
i.e. scipy's intrinsic ``"ZXY"`` sequence. Gimbal angle arrays are ordered (outer, middle, inner).
Rotations are plain numpy matrices here (the tests check them against scipy's ``Rotation``): importing
scipy's spatial package would add 0.1 s to the start-up of every trial.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from hil.units import DEG

if TYPE_CHECKING:
    from hil.config import SiteConfig, TurntableConfig  # the schemas are needed for the annotations only

EARTH_RATE = 7.2921151467e-5  # rad/s, WGS-84
WGS84_A = 6378137.0  # m, semi-major axis
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = 0.00669437999013
WGS84_GE = 9.7803253359  # m/s^2, normal gravity at the equator
WGS84_K = 0.00193185265241  # Somigliana constant
WGS84_M = 0.00344978650684  # omega^2 a^2 b / GM

EULER_SEQ = "ZXY"  # yaw (z), pitch (x), roll (y); intrinsic


def normal_gravity(latitude: float, height: float = 0.0) -> float:
    """WGS-84 normal gravity (m/s^2) at geodetic latitude (rad) and ellipsoidal height (m).

    Somigliana's closed form on the ellipsoid, with the second-order free-air correction in height.
    """
    s2 = math.sin(latitude) ** 2
    g0 = WGS84_GE * (1.0 + WGS84_K * s2) / math.sqrt(1.0 - WGS84_E2 * s2)
    c1 = 2.0 / WGS84_A * (1.0 + WGS84_F + WGS84_M - 2.0 * WGS84_F * s2)
    return g0 * (1.0 - c1 * height + 3.0 * height**2 / WGS84_A**2)


@dataclass(frozen=True)
class Earth:
    """Site-dependent earth quantities in the ENU navigation frame."""

    latitude: float  # rad
    height: float = 0.0  # m

    @property
    def g(self) -> float:
        return normal_gravity(self.latitude, self.height)

    @property
    def omega_n(self) -> np.ndarray:
        """Earth rate in n (ENU): [0, W cos L, W sin L]."""
        return EARTH_RATE * np.array([0.0, math.cos(self.latitude), math.sin(self.latitude)])

    @property
    def f_n(self) -> np.ndarray:
        """Specific force sensed at rest, in n: [0, 0, g]."""
        return np.array([0.0, 0.0, self.g])

    def turn_matrices(self, t: np.ndarray) -> np.ndarray:
        """C_n^n0(t), the navigation frame at t seen in the start navigation frame (the earth's turn), as
        (N, 3, 3) matrices by Rodrigues' formula about the fixed earth axis u:
        ``I + sin(Wt) [u x] + 2 sin^2(Wt/2) [u x]^2`` (no cancellation at small angles)."""
        angle = EARTH_RATE * np.asarray(t, dtype=float).reshape(-1, 1, 1)
        eye, k, k2 = self._rodrigues_terms
        return eye + np.sin(angle) * k + (2.0 * np.sin(0.5 * angle) ** 2) * k2

    @cached_property
    def _rodrigues_terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """I, ``[u x]`` and ``[u x]^2`` of the earth axis u, formed once."""
        k = skew(self.omega_n / EARTH_RATE)
        return np.eye(3), k, k @ k

    @classmethod
    def from_degrees(cls, latitude_deg: float, height_m: float = 0.0) -> Earth:
        return cls(latitude_deg * DEG, height_m)

    @classmethod
    def from_config(cls, site: SiteConfig) -> Earth:
        """The Earth at a config's ``site``."""
        return cls.from_degrees(site.latitude_deg, site.height_m)


def site_specific_force(earth: Earth, deflection: tuple[float, float] = (0.0, 0.0), anomaly: float = 0.0) -> np.ndarray:
    """Specific force at rest in n (ENU) under the site's true gravity, m/s^2.

    Magnitude ``g + anomaly``; direction the plumb line's zenith, which the deflection of the vertical
    (xi, eta) rad turns north and east of the ellipsoid normal (2018 gravity-vector paper, Sec. 2.1,
    eq. 1: ``tan xi = dg_N / g``, ``tan eta = dg_E / g``, the true gravity pointing further south and
    west for positive components). Zero deflection and anomaly give :attr:`Earth.f_n` exactly.
    """
    xi, eta = deflection
    up = np.array([math.tan(eta), math.tan(xi), 1.0])
    return (earth.g + anomaly) * up / np.linalg.norm(up)


def euler_matrix(yaw_pitch_roll: np.ndarray) -> np.ndarray:
    """Rz(yaw) Rx(pitch) Ry(roll) from angles (rad): (3, 3) from shape (3,), (N, 3, 3) from (N, 3)."""
    angles = np.asarray(yaw_pitch_roll, dtype=float)
    rows = np.atleast_2d(angles)
    rz, rx, ry = _euler_factors(rows)
    m = rz @ rx @ ry
    return m[0] if angles.ndim == 1 else m


def rotation_vector_matrix(v: Sequence[float]) -> np.ndarray:
    """The rotation matrix of a rotation vector v (rad), by Rodrigues' formula about ``u = v / |v|``:
    ``I + sin|v| [u x] + 2 sin^2(|v|/2) [u x]^2``."""
    angle = math.hypot(*v)
    if angle == 0.0:
        return np.eye(3)
    k = skew(np.asarray(v, dtype=float) / angle)
    return np.eye(3) + math.sin(angle) * k + 2.0 * math.sin(0.5 * angle) ** 2 * (k @ k)


def wrapped(angle: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped to [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def level_angles(up: np.ndarray) -> np.ndarray:
    """(pitch, roll), (..., 2), of C_b^n matrices from their last row (the up axis in b): C32 = sin p,
    C31 = -cos p sin r, C33 = cos p cos r (pitch within +-90 deg)."""
    up = np.asarray(up, dtype=float)
    return np.stack((np.arcsin(np.clip(up[..., 1], -1.0, 1.0)), np.arctan2(-up[..., 0], up[..., 2])), axis=-1)


def euler_from_matrix(c: np.ndarray) -> np.ndarray:
    """(yaw, pitch, roll), (..., 3), of C_b^n matrices (..., 3, 3) in closed form (pitch within +-90 deg).

    From ``Rz(y) Rx(p) Ry(r)``: C12 = -sin y cos p, C22 = cos y cos p, and :func:`level_angles`.
    """
    yaw = np.arctan2(-c[..., 0, 1], c[..., 1, 1])
    return np.concatenate((yaw[..., None], level_angles(c[..., 2, :])), axis=-1)


@dataclass(frozen=True)
class TableGeometry:
    """How the turntable sits on the site and how the IMU sits on the inner gimbal."""

    azimuth: float = 0.0  # rad, rotation of the outer-axis zero about up (same sense as the outer angle)
    tilt: tuple[float, float] = (0.0, 0.0)  # rad, base tilt about east (x) and north (y)
    mounting: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad, (yaw, pitch, roll) of b in the inner gimbal

    @classmethod
    def from_config(cls, table: TurntableConfig) -> TableGeometry:
        return cls(
            table.azimuth_deg * DEG,
            (table.tilt_deg[0] * DEG, table.tilt_deg[1] * DEG),
            tuple(a * DEG for a in table.mounting_deg),
        )

    @cached_property
    def table_to_n_matrix(self) -> np.ndarray:
        """C_table^n = R_tilt . Rz(azimuth), (3, 3), formed once."""
        return rotation_vector_matrix((self.tilt[0], self.tilt[1], 0.0)) @ _axis_matrices(np.array([self.azimuth]), 2)[0]

    @cached_property
    def body_to_mount_matrix(self) -> np.ndarray:
        """C_b^mount: the IMU case in the inner gimbal frame, (3, 3), formed once."""
        return euler_matrix(np.asarray(self.mounting))

    def attitude_matrix(self, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """C_b^n = C_table^n . Rz(outer) Rx(middle) Ry(inner) . C_b^mount from angles (rad) (3,) or (N, 3), with
        the two inner products :meth:`body_rate_from` needs: (C_b^n, Rx(middle) Ry(inner), Ry(inner)), each (N, 3, 3).
        """
        angles = np.atleast_2d(angles)
        rz, rx, ry = _euler_factors(angles)
        inner = ry
        middle_inner = rx @ ry
        c_bn = self.table_to_n_matrix @ rz @ middle_inner @ self.body_to_mount_matrix
        return c_bn, middle_inner, inner

    def body_rate_from(self, middle_inner: np.ndarray, inner: np.ndarray, angle_rates: np.ndarray) -> np.ndarray:
        """omega_nb^b (rad/s) from the matrices of :meth:`attitude_matrix` and the gimbal rates (N, 3).

        omega = C_mount^b [ Ry(i)^T Rx(m)^T z * d(outer) + Ry(i)^T x * d(middle) + y * d(inner) ].
        """
        rates = np.atleast_2d(angle_rates)
        w_mount = middle_inner[:, 2, :] * rates[:, 0:1] + inner[:, 0, :] * rates[:, 1:2]
        w_mount[:, 1] += rates[:, 2]
        return w_mount @ self.body_to_mount_matrix



def table_body_rotation(geometry: TableGeometry, earth: Earth, dt: np.ndarray, angles_start: np.ndarray,
                        angles_end: np.ndarray) -> np.ndarray:
    """The body's rotation in inertial space over intervals of length ``dt`` (N,) from the gimbal angles
    (N, 3) at both ends: ``C_n^b(t1) C_n(t2)^n(t1) C_b^n(t2)`` (the earth's turn included), (N, 3, 3)."""
    start, end = np.atleast_2d(angles_start), np.atleast_2d(angles_end)
    c = geometry.attitude_matrix(np.vstack((start, end)))[0]
    n = len(start)
    return np.swapaxes(c[:n], 1, 2) @ (earth.turn_matrices(dt) @ c[n:])


def _euler_factors(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rz, Rx and Ry of angle rows (N, 3) in the gimbal order (outer or yaw, middle or pitch, inner or roll),
    each (N, 3, 3)."""
    rz, rx, ry = (_axis_matrices(rows[:, k], axis) for k, axis in enumerate((2, 0, 1)))
    return rz, rx, ry


def _axis_matrices(angle: np.ndarray, axis: int) -> np.ndarray:
    """Elementary rotations about one coordinate axis (0 = x, 1 = y, 2 = z), (N, 3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    m = np.zeros((len(angle), 3, 3))
    m[:, axis, axis] = 1.0
    m[:, i, i] = m[:, j, j] = c
    m[:, j, i] = s
    m[:, i, j] = -s
    return m


def skew(v: np.ndarray) -> np.ndarray:
    """The cross-product matrix [v x] of a 3-vector."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
