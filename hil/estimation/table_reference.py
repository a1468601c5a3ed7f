"""Turntable-referenced accelerometer bias: the independent check on the self-calibrated one.

With the table angles as the attitude reference, the mean specific force over each interval is
``f_b = C_n^b (I - [delta x]) f^n + bias`` where ``delta = (dx, dy, 0)`` is a small tilt of the table
base not in the configuration; linearised, ``f_b - C_n^b f^n = bias + C_n^b [f^n x] delta``. The
least-squares solution of this is what a separated calibration on the table gives. The azimuth of
the table never enters (a rotation about the vertical leaves gravity unchanged), and the tilt is kept
as an unknown only when the motion makes it observable.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hil.estimation.gimbal import row_times
from hil.estimation.normal_equations import NormalEquations, symmetric_eigenvalues
from hil.frames import skew


@dataclass(frozen=True)
class TableReferencedBias:
    bias: np.ndarray | None  # (3,) m/s^2
    bias_sigma: np.ndarray | None
    tilt: np.ndarray | None  # (2,) rad about east and north, when observable
    samples: int


class TableReferenceEstimator:
    """Normal equations of the 5-unknown (bias, tilt) table-referenced model."""

    def __init__(self, f_n: np.ndarray, rank_tolerance: float = 1e-6) -> None:
        self.f_n = f_n
        self.rank_tolerance = rank_tolerance
        self.normal = NormalEquations(5)

    def update_segments(self, f_b: np.ndarray, c_bn_mean: np.ndarray, stops: Sequence[int],
                        accept: np.ndarray | None = None) -> Iterator[int]:
        """Add N measured mean specific forces (N, 3) with the mean table attitude C_b^n over each interval
        ((3, 3, N), component-major: :mod:`hil.estimation.gimbal`), yielding after the samples up to each
        stop are in; ``accept`` False leaves a sample out."""
        z = f_b - row_times(self.f_n, c_bn_mean).T  # C_n^b f^n
        tilt = skew(self.f_n)
        h = np.zeros((len(z), 3, 5))
        h[:, :, :3] = np.eye(3)
        for j in range(2):  # (C_n^b [f^n x])[:, j] = C^T column j
            h[:, :, 3 + j] = row_times(tilt[:, j], c_bn_mean).T
        yield from self.normal.add_segments(h, z, stops, accept)

    def solve(self) -> TableReferencedBias:
        normal = self.normal
        if normal.samples < 2:
            return TableReferencedBias(None, None, None, normal.samples)
        n = 5 if self._tilt_observable() else 3
        info, rhs = normal.info[:n, :n], normal.rhs[:n]
        cov = np.linalg.inv(info)
        x = cov @ rhs
        rss = max(normal.zz - float(x @ rhs), 0.0)
        noise_var = rss / max(3 * normal.samples - n, 1)
        sigma = np.sqrt(noise_var * np.diag(cov))
        return TableReferencedBias(x[:3], sigma[:3], x[3:] if n == 5 else None, normal.samples)

    def _tilt_observable(self) -> bool:
        scaled, _ = self.normal.scaled(5)
        eig = symmetric_eigenvalues(scaled)
        return bool(eig[0] > self.rank_tolerance * eig[-1])
