"""Truth model: commanded gimbal motion -> body attitude -> ideal IMU increments.

The IMU sits at the turntable's centre of rotation on a site fixed to the rotating earth, so the
specific force is ``f^b = C_n^b f^n`` with ``f^n`` the site's true gravity reversed (normal gravity
``[0, 0, g]`` turned by the deflection of the vertical and scaled by the anomaly:
:func:`hil.frames.site_specific_force`) and the angular rate is
``omega_ib^b = omega_nb^b + C_n^b omega_ie^n``. Increments over each sample interval are the exact
integrals of these, evaluated with Gauss-Legendre quadrature of the analytic motion (never by
differencing attitudes), so error-free data through the estimator gives zero bias. Intervals are
split at the motion's kinks (:func:`emulators.motion.motion_breaks`), so a rate step or a change
of acceleration inside an interval costs no accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from emulators.motion import MotionProfile, motion_breaks
from hil.estimation.gimbal import gimbal_matrices, row_times
from hil.frames import Earth, TableGeometry, site_specific_force

QUADRATURE_NODES = 3  # exact for polynomials of degree 5 over one sample interval
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(QUADRATURE_NODES)


@dataclass(frozen=True)
class Truth:
    """The emulated world: site, turntable geometry and commanded motion."""

    earth: Earth
    geometry: TableGeometry
    motion: MotionProfile
    deflection: tuple[float, float] = (0.0, 0.0)  # rad, deflection of the vertical (xi north, eta east)
    gravity_anomaly: float = 0.0  # m/s^2, true minus normal gravity magnitude

    @cached_property
    def f_n(self) -> np.ndarray:
        """Specific force at rest in n under the site's true gravity."""
        return site_specific_force(self.earth, self.deflection, self.gravity_anomaly)

    def angles(self, t: np.ndarray) -> np.ndarray:
        """Gimbal angles (N, 3), rad, ordered (outer, middle, inner)."""
        return self.motion(np.asarray(t, dtype=float))[0]

    def rates_and_forces(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """omega_ib^b (rad/s) and f^b (m/s^2) at instants t (N,), each component-major (3, N); the body rate
        as :meth:`hil.frames.TableGeometry.body_rate_from` forms it."""
        angles, angle_rates = self.motion(t)
        c_bn, middle_inner = gimbal_matrices(self.geometry, angles)
        rates = angle_rates.T
        w_mount = middle_inner[2] * rates[0] + middle_inner[0] * rates[1]
        w_mount[1] += rates[2]
        omega = self.geometry.body_to_mount_matrix.T @ w_mount + row_times(self.earth.omega_n, c_bn)
        return omega, row_times(self.f_n, c_bn)

    def increments(self, t_start: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal (dtheta, dv) over the intervals (t[k-1], t[k]], with t[-1] = t_start; each (N, 3)."""
        t = np.asarray(t, dtype=float)
        ends = np.concatenate(([t_start], t))
        breaks = motion_breaks(self.motion, t_start, float(t[-1])) if len(t) else np.empty(0)
        edges = np.union1d(ends, breaks) if len(breaks) else ends
        half = 0.5 * np.diff(edges)
        mid = 0.5 * (edges[1:] + edges[:-1])
        times = (mid[:, None] + half[:, None] * _NODES[None, :]).ravel()
        omega, force = self.rates_and_forces(times)
        w = half[:, None] * _WEIGHTS[None, :]
        n = len(edges) - 1
        dtheta = np.einsum("ink,nk->ni", omega.reshape(3, n, QUADRATURE_NODES), w)
        dv = np.einsum("ink,nk->ni", force.reshape(3, n, QUADRATURE_NODES), w)
        if len(breaks):  # sum the pieces of each split interval
            first = np.searchsorted(edges, ends[:-1])
            dtheta, dv = np.add.reduceat(dtheta, first), np.add.reduceat(dv, first)
        return dtheta, dv
