"""Turntable-referenced accelerometer bias: the independent check on the self-calibrated one.

With the table angles as the attitude reference, the mean specific force over each interval is
``f_b = C_n^b (I - [delta x]) f^n + bias`` where ``delta = (dx, dy, 0)`` is a small tilt of the table
base not in the configuration; linearised, ``f_b - C_n^b f^n = bias + C_n^b [f^n x] delta``. The
least-squares solution of this is what a separated calibration on the table gives. The azimuth of
the table never enters (a rotation about the vertical leaves gravity unchanged), and the tilt is kept
as an unknown only when the motion makes it observable.

The drift columns ``I t`` (2018 gravity-vector paper, eq. 90: ``bias = b_s + k t``, t in s from the trial
start) are summed as the border of the same normal equations, so the constant-bias fit is unchanged by
them, and the drift rate k is solved beside it. It needs no gyro: where the self-calibrated drift check
(15-state model) and this one disagree, the apparent drift is not the accelerometer's.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hil.estimation.apparent_gravity import DRIFT_SIGNIFICANCE
from hil.estimation.gimbal import row_times
from hil.estimation.normal_equations import NormalEquations, symmetric_eigenvalues, unit_diagonal
from hil.frames import skew


def drifts_agree(drift: Sequence[float], sigma: Sequence[float], table_drift: Sequence[float],
                 table_sigma: Sequence[float], sigmas: float = DRIFT_SIGNIFICANCE) -> bool:
    """Whether the self-calibrated drift rates (the 15-state model's) and the table-referenced ones agree within
    ``sigmas`` of their combined sigma on every axis (any one unit for all four). Both come from the same
    accelerometer samples, so the difference varies less than the combined sigma says: the test leans
    towards agreement, towards a drift that is the accelerometer's."""
    difference = np.abs(np.asarray(drift) - np.asarray(table_drift))
    return bool((difference <= sigmas * np.hypot(sigma, table_sigma)).all())


@dataclass(frozen=True)
class TableReferencedBias:
    bias: np.ndarray | None  # (3,) m/s^2
    bias_sigma: np.ndarray | None
    tilt: np.ndarray | None  # (2,) rad about east and north, when observable
    samples: int
    drift: np.ndarray | None = None  # (3,) m/s^3: k of bias = b_s + k t, fitted beside the constant bias
    drift_sigma: np.ndarray | None = None


class TableReferenceEstimator:
    """Normal equations of the 5-unknown (bias, tilt) table-referenced model, with the 3 drift rates as their border."""

    def __init__(self, f_n: np.ndarray, rank_tolerance: float = 1e-6) -> None:
        self.f_n = f_n
        self.rank_tolerance = rank_tolerance
        self.normal = NormalEquations(5, border=3)

    def update_segments(self, t_mid: np.ndarray, f_b: np.ndarray, c_bn_mean: np.ndarray, stops: Sequence[int],
                        accept: np.ndarray | None = None) -> Iterator[int]:
        """Add N measured mean specific forces (N, 3) at the interval midpoints ``t_mid`` (N,; s from the trial
        start) with the mean table attitude C_b^n over each interval ((3, 3, N), component-major:
        :mod:`hil.estimation.gimbal`), yielding after the samples up to each stop are in; ``accept`` False
        leaves a sample out."""
        z = f_b - row_times(self.f_n, c_bn_mean).T  # C_n^b f^n
        tilt = skew(self.f_n)
        h = np.zeros((len(z), 3, 5))
        h[:, :, :3] = np.eye(3)
        for j in range(2):  # (C_n^b [f^n x])[:, j] = C^T column j
            h[:, :, 3 + j] = row_times(tilt[:, j], c_bn_mean).T
        g = np.eye(3) * t_mid[:, None, None]
        yield from self.normal.add_segments(h, z, stops, accept, g=g)

    def solve(self) -> TableReferencedBias:
        normal = self.normal
        if normal.samples < 2:
            return TableReferencedBias(None, None, None, normal.samples)
        n = 5 if self._full_rank(normal.scaled(5)[0]) else 3
        x, sigma = self._fit(np.linalg.inv(normal.info[:n, :n]), normal.rhs[:n])
        return TableReferencedBias(x[:3], sigma[:3], x[3:] if n == 5 else None, normal.samples, *self._drift(n))

    def _drift(self, n: int) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The drift rates and their sigmas of the model with the first ``n`` unknowns and the drift; None while
        the data do not tell a drift from a constant bias."""
        keep = np.r_[0:n, 5:8]
        scaled, scale = unit_diagonal(self.normal.info[np.ix_(keep, keep)])
        if not self._full_rank(scaled):
            return None, None
        x, sigma = self._fit(np.linalg.inv(scaled) * np.outer(scale, scale), self.normal.rhs[keep])
        return x[n:], sigma[n:]

    def _fit(self, cov: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The least-squares solution of the unknowns whose inverse normal matrix is ``cov`` and whose ``H^T z``
        is ``rhs``, and its sigmas, with the noise level from the residual sum of squares."""
        x = cov @ rhs
        rss = max(self.normal.zz - float(x @ rhs), 0.0)
        noise_var = rss / max(3 * self.normal.samples - len(rhs), 1)
        return x, np.sqrt(noise_var * np.diag(cov))

    def _full_rank(self, scaled: np.ndarray) -> bool:
        """Whether a unit-diagonal normal matrix has no eigenvalue below ``rank_tolerance`` times its largest."""
        eig = symmetric_eigenvalues(scaled)
        return bool(eig[0] > self.rank_tolerance * eig[-1])
