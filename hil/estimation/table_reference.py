"""Turntable-referenced accelerometer bias: the independent check on the self-calibrated one.

With the table angles as the attitude reference, the mean specific force over each interval is
``f_b = C_n^b (I - [delta x]) f^n + bias`` where ``delta = (dx, dy, 0)`` is a small tilt of the table
base not in the configuration; linearised, ``f_b - C_n^b f^n = bias + C_n^b [f^n x] delta``. The
least-squares solution of this is what a separated calibration on the table gives. The azimuth of
the table never enters (a rotation about the vertical leaves gravity unchanged), and the tilt is kept
as an unknown only when the motion makes it observable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh

from hil.frames import skew


@dataclass(frozen=True)
class TableReferencedBias:
    bias: np.ndarray | None  # (3,) m/s^2
    bias_sigma: np.ndarray | None
    tilt: np.ndarray | None  # (2,) rad about east and north, when observable
    samples: int


class TableReferenceEstimator:
    """Accumulates the normal equations of the 5-unknown (bias, tilt) table-referenced model."""

    def __init__(self, f_n: np.ndarray, rank_tolerance: float = 1e-6) -> None:
        self.f_n = f_n
        self.rank_tolerance = rank_tolerance
        self.info = np.zeros((5, 5))
        self.rhs = np.zeros(5)
        self.zz = 0.0
        self.samples = 0

    def update_many(self, f_b: np.ndarray, c_bn_mean: np.ndarray) -> None:
        """Add N measured mean specific forces (N, 3) with the mean table attitude C_b^n over each interval (N, 3, 3)."""
        c_nb = np.swapaxes(c_bn_mean, 1, 2)
        z = f_b - c_nb @ self.f_n
        tilt_cols = (c_nb @ skew(self.f_n))[:, :, :2]
        h = np.concatenate((np.broadcast_to(np.eye(3), (len(z), 3, 3)), tilt_cols), axis=2)
        self.info += np.einsum("nri,nrj->ij", h, h)
        self.rhs += np.einsum("nri,nr->i", h, z)
        self.zz += float(np.einsum("ni,ni->", z, z))
        self.samples += len(z)

    def solve(self) -> TableReferencedBias:
        if self.samples < 2:
            return TableReferencedBias(None, None, None, self.samples)
        n = 5 if self._tilt_observable() else 3
        info, rhs = self.info[:n, :n], self.rhs[:n]
        cov = np.linalg.inv(info)
        x = cov @ rhs
        rss = max(self.zz - float(x @ rhs), 0.0)
        noise_var = rss / max(3 * self.samples - n, 1)
        sigma = np.sqrt(noise_var * np.diag(cov))
        return TableReferencedBias(x[:3], sigma[:3], x[3:] if n == 5 else None, self.samples)

    def _tilt_observable(self) -> bool:
        d = 1.0 / np.sqrt(np.diag(self.info))
        eig = eigh(self.info * np.outer(d, d), eigvals_only=True)
        return bool(eig[0] > self.rank_tolerance * eig[-1])
