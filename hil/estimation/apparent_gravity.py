"""Gravitational apparent acceleration model and accelerometer bias, by recursive least squares.

Model (2019 eqs. 9-15): ``f^ib0(t) = A [cos wt, sin wt, 1]^T + C_b^ib0(t) bias + noise`` with the
12-state vector ``[A11..A33, bx, by, bz]``; without the bias columns it is the 9-state model of the
2014 paper ("method 1"). With the bias split into repeatability and linear drift (2018 gravity-vector
paper, eq. 90: ``bias = b_s + k t``) it is the 15-state model ``[A11..A33, b_s, k]``. Each IMU
increment gives one 3-row measurement: the mean specific force in i_b0 over its interval, against
the interval means of the regressors.

The recursion is kept in information form: the normal matrix ``W = sum H^T H`` (the observability
Gram matrix of 2019 eq. 19 in discrete form) and ``sum H^T z`` are accumulated per sample and solved
when a solution is asked for (the display rate). This equals batch least squares exactly and stays sound over a
24-hour trial, where covariance-form RLS with a large P0 does not. Two numerical choices:

- the gravity basis is held as ``[1 - cos wt, sin wt, 1]`` (about ``t^2/2, t, 1`` early in a trial),
  whose sums carry no cancellation; ``A`` in the paper's basis is recovered exactly;
- ``W`` is judged and solved after symmetric diagonal scaling (unit diagonal), so rank and
  condition number describe the motion, not the units.

The drift columns ``C_b^ib0 t`` (t in s from the trial start) are summed as the border of the same
normal equations on every trial, so the 9- and 12-state blocks are unchanged by them and a drift can
be checked whatever the model. The 15-state system is solved with the time origin moved to the middle
of the data so far, ``b = b_c + k (t - t/2)``: an exact change of parameters that makes the bias and
drift columns nearly orthogonal before the scaling (the fit itself does not depend on the origin).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hil.estimation.normal_equations import NormalEquations, require_finite, symmetric_eigenvalues, unit_diagonal
from hil.frames import EARTH_RATE
from hil.units import HOUR, UG

N_GRAVITY = 9  # A11..A33
N_FULL = 12  # plus bias x, y, z
N_DRIFT = 15  # plus bias drift rate x, y, z
DRIFT_SIGNIFICANCE = 4.0  # a drift beyond this many sigma on some axis is significant
DRIFT_FLOOR = 1e-3 * UG / HOUR  # m/s^3: a sigma below 0.001 ug/h is the arithmetic's, not the data's (noise-free input)
_TINY = np.finfo(float).tiny
_IDENTITY = np.eye(N_DRIFT)  # read-only: copied or sliced, never written
_IDENTITY.setflags(write=False)


def gravity_basis(t_start: np.ndarray, t_end: np.ndarray, omega: float = EARTH_RATE) -> np.ndarray:
    """Interval means of ``[1 - cos wt, sin wt, 1]`` over (t_start, t_end], (N, 3), free of cancellation."""
    half = 0.5 * omega * (t_end - t_start)
    mid = 0.5 * omega * (t_end + t_start)
    sinc = np.sinc(half / np.pi)  # sin(h)/h
    one_minus_sinc = np.where(np.abs(half) < 1e-4, half**2 / 6.0 - half**4 / 120.0, 1.0 - sinc)
    one_minus_cos = 2.0 * np.sin(0.5 * mid) ** 2 + np.cos(mid) * one_minus_sinc
    return np.column_stack((one_minus_cos, np.sin(mid) * sinc, np.ones_like(mid)))


def reconstruction_basis(t: np.ndarray | float, omega: float = EARTH_RATE) -> np.ndarray:
    """The internal basis ``[1 - cos wt, sin wt, 1]`` at instants t, (N, 3): ``f^ib0(t) = basis A^T`` (2014 eq. 17)."""
    wt = omega * np.atleast_1d(np.asarray(t, dtype=float))
    basis = np.ones((len(wt), 3))
    basis[:, 0] = 2.0 * np.sin(0.5 * wt) ** 2
    basis[:, 1] = np.sin(wt)
    return basis


def paper_basis_matrix(a_internal: np.ndarray) -> np.ndarray:
    """A in the paper's basis [cos, sin, 1] from A in the internal basis [1 - cos, sin, 1]."""
    a = a_internal.copy()
    a[:, 0] = -a_internal[:, 0]
    a[:, 2] = a_internal[:, 2] + a_internal[:, 0]
    return a


@dataclass(frozen=True)
class Observability:
    """Rank and conditioning of the scaled Gram matrix (2019 eqs. 17-19)."""

    rank: int
    condition: float
    eigenvalues: np.ndarray

    def full(self, n: int) -> bool:
        return self.rank == n


@dataclass(frozen=True)
class Solution:
    """A least-squares solution of the 15-state (bias and drift), 12-state (bias) or 9-state model at time ``t``.

    With drift, ``bias`` is the bias at ``t`` (``b_s + k t``) and ``bias_t0`` the repeatability ``b_s``
    (the bias at t = 0); without, the two ``drift`` fields and ``bias_t0`` are None.
    """

    t: float
    samples: int
    a_internal: np.ndarray  # (3, 3) in the basis [1 - cos wt, sin wt, 1]
    bias: np.ndarray | None  # (3,) m/s^2, None for the 9-state model or when unobservable
    bias_sigma: np.ndarray | None  # (3,) m/s^2, 1-sigma
    noise_sigma: float  # m/s^2, residual RMS per axis and sample
    observability: Observability
    observable: bool
    states: int = N_FULL
    bias_t0: np.ndarray | None = None  # (3,) m/s^2, b_s
    bias_t0_sigma: np.ndarray | None = None
    drift: np.ndarray | None = None  # (3,) m/s^3 (m/s^2 per s), k
    drift_sigma: np.ndarray | None = None

    @property
    def a(self) -> np.ndarray:
        """A11..A33 as in 2019 eq. 9 (basis [cos wt, sin wt, 1])."""
        return paper_basis_matrix(self.a_internal)

    def apparent_gravity(self, t: np.ndarray | float, omega: float = EARTH_RATE) -> np.ndarray:
        """Reconstructed gravitational apparent acceleration f^ib0 at instants t (2014 eq. 17), (N, 3)."""
        return reconstruction_basis(t, omega) @ self.a_internal.T


@dataclass(frozen=True)
class DriftCheck:
    """The bias drift rate of the 15-state model, formed on every trial so that an unmodelled drift shows."""

    drift: np.ndarray  # (3,) m/s^3
    sigma: np.ndarray  # (3,) m/s^3, 1-sigma
    significant: bool  # some axis beyond DRIFT_SIGNIFICANCE sigma (a sigma under DRIFT_FLOOR counts as DRIFT_FLOOR)

    @classmethod
    def from_solution(cls, solution: Solution) -> DriftCheck | None:
        """The check from a 15-state solution; None while the drift is not observable."""
        if solution.drift is None:
            return None
        sigma = np.maximum(solution.drift_sigma, DRIFT_FLOOR)
        significant = bool((np.abs(solution.drift) > DRIFT_SIGNIFICANCE * sigma).any())
        return cls(solution.drift, solution.drift_sigma, significant)


def measurement_matrix(t_start: np.ndarray, t_end: np.ndarray, c_mean: np.ndarray, omega: float = EARTH_RATE) -> np.ndarray:
    """H (N, 3, 12) of 2019 eq. 14 over each interval: row r is ``[e_r (x) w^T, C[r, :]]``."""
    w = gravity_basis(t_start, t_end, omega)
    h = np.zeros((len(w), 3, N_FULL))
    for r in range(3):
        h[:, r, 3 * r : 3 * r + 3] = w
    h[:, :, N_GRAVITY:] = c_mean
    return h


def drift_columns(t_start: np.ndarray, t_end: np.ndarray, c_mean: np.ndarray) -> np.ndarray:
    """G (N, 3, 3): the drift regressor ``C_b^ib0 t`` over each interval, as ``mean(C) t_mid``.

    The interval mean of ``C t`` differs from it by ``dC/dt dt^2 / 12``, times k a few 1e-12 ug at 200 Hz.
    """
    return c_mean * (0.5 * (t_start + t_end))[:, None, None]


class ApparentGravityEstimator:
    """Normal equations of the 15-state model; the 12- and 9-state models are their leading blocks."""

    def __init__(self, rank_tolerance: float = 1e-6, omega: float = EARTH_RATE) -> None:
        self.rank_tolerance = rank_tolerance
        self.omega = omega
        self.normal = NormalEquations(N_FULL, border=N_DRIFT - N_FULL)
        self.t = 0.0

    @property
    def samples(self) -> int:
        return self.normal.samples

    def update_many(self, t_start: np.ndarray, t_end: np.ndarray, f_ib0: np.ndarray, c_mean: np.ndarray) -> None:
        """Add N measurements: mean specific force in i_b0 (N, 3) and the mean of C_b^ib0 over each interval (N, 3, 3)."""
        for _ in self.update_segments(t_start, t_end, f_ib0, c_mean, [len(t_end)]):
            pass

    def update_segments(
        self, t_start: np.ndarray, t_end: np.ndarray, f_ib0: np.ndarray, c_mean: np.ndarray, stops: Sequence[int],
        accept: np.ndarray | None = None,
    ) -> Iterator[int]:
        """As :meth:`update_many`, yielding after the samples up to each stop are in (to solve there);
        samples with ``accept`` False are left out."""
        h = measurement_matrix(t_start, t_end, c_mean, self.omega)
        g = drift_columns(t_start, t_end, c_mean)
        for stop in self.normal.add_segments(h, f_ib0, stops, accept, g=g):
            self.t = float(t_end[stop - 1])
            yield stop

    def sums(self) -> Sums:
        """The normal equations now (a copy)."""
        return Sums(self.normal.info.copy(), self.normal.rhs.copy(), self.normal.zz, self.samples, self.t)

    def observability(self, n: int = N_FULL) -> Observability:
        """Rank and condition number of the diagonally scaled Gram matrix of the first n states."""
        scaled = unit_diagonal(self._normal_equations([self.sums()], n)[0])[0]
        return _observability(symmetric_eigenvalues(scaled)[0], self.rank_tolerance)

    def solve(self, states: int = N_FULL) -> Solution:
        """The least-squares solution now: 15-state (bias and drift), 12-state (bias) or 9-state ("method 1")."""
        return self.solve_nested((states,))[0]

    def solve_nested(self, states: Sequence[int]) -> list[Solution]:
        """:meth:`solve` for several of the nested models at once, e.g. ``(N_DRIFT, N_FULL, N_GRAVITY)``."""
        return self.solve_many([self.sums()], states)[0]

    def solve_many(self, instants: Sequence[Sums], states: Sequence[int]) -> list[list[Solution]]:
        """:meth:`solve_nested` at several instants (the solve instants one batch of samples passes).

        The normal equations are formed and scaled once, for the largest model; the scaled systems of
        the others are its leading blocks, bit for bit (the re-centring of the 15-state model leaves
        the first 12 rows and columns as they are, and the scale factors are per state). Scaling,
        eigenvalues and solves run over the stack of instants; LAPACK solves each matrix of a stack on
        its own, so an instant's solution is the same to the bit however many are stacked.
        """
        info, rhs = self._normal_equations(instants, max(states))
        scaled, scale = unit_diagonal(info)
        require_finite(scaled)  # once: its leading blocks are then finite too
        rhs = rhs * scale
        out: list[list[Solution]] = [[] for _ in instants]
        for n in states:
            block = np.ascontiguousarray(scaled[:, :n, :n])
            obs = [_observability(eig, self.rank_tolerance) for eig in symmetric_eigenvalues(block, check_finite=False)]
            full = np.array([o.full(n) for o in obs])
            solved = np.empty((len(instants), n, 1 + n - N_GRAVITY))
            if full.any():  # positive definite: y and the inverse's bias and drift columns in one solve
                columns = np.broadcast_to(_IDENTITY[:n, N_GRAVITY:n], (int(full.sum()), n, n - N_GRAVITY))
                solved[full] = np.linalg.solve(block[full], np.concatenate((rhs[full, :n, None], columns), axis=2))
            for k, sums in enumerate(instants):
                if full[k]:
                    y, inverse_columns = solved[k, :, 0], solved[k, :, 1:]
                else:
                    y, inverse_columns = np.linalg.lstsq(block[k], rhs[k, :n], rcond=self.rank_tolerance)[0], None
                out[k].append(self._solution(sums, block[k], rhs[k, :n], scale[k, :n], y, inverse_columns, obs[k]))
        return out

    @staticmethod
    def _solution(sums: Sums, scaled: np.ndarray, rhs: np.ndarray, scale: np.ndarray, y: np.ndarray,
                  inverse_columns: np.ndarray | None, obs: Observability) -> Solution:
        """The solution of the first n states from the solution y of their scaled normal equations
        (``scaled y = rhs``, ``x = scale y``), with the noise level from the residual sum of squares;
        ``inverse_columns`` the scaled inverse's bias and drift columns, None when not observable."""
        n = len(rhs)
        x = y * scale
        dof = max(3 * sums.samples - n, 1)
        rss = max(sums.zz - 2.0 * float(y @ rhs) + float(y @ scaled @ y), 0.0)
        noise_var = rss / dof
        bias_fields: dict[str, np.ndarray | None] = {"bias": None, "bias_sigma": None}
        if inverse_columns is not None and n > N_GRAVITY:
            bias_fields = _bias_and_drift(x, inverse_columns[N_GRAVITY:], scale, noise_var, sums.t)
        return Solution(
            t=sums.t,
            samples=sums.samples,
            a_internal=x[:N_GRAVITY].reshape(3, 3),
            noise_sigma=math.sqrt(noise_var),
            observability=obs,
            observable=inverse_columns is not None,
            states=n,
            **bias_fields,
        )

    @staticmethod
    def _normal_equations(instants: Sequence[Sums], n: int) -> tuple[np.ndarray, np.ndarray]:
        """The normal matrices (K, n, n) and right-hand sides (K, n) of the first n states at K instants; for
        15 states with the drift's time origin at :func:`drift_origin` (``H' = H T``: the drift column
        ``C (t - tau)``)."""
        info = np.stack([sums.info[:n, :n] for sums in instants])
        rhs = np.stack([sums.rhs[:n] for sums in instants])[..., None]
        if n == N_DRIFT:
            change = np.repeat(_IDENTITY[None], len(instants), axis=0)
            origins = np.array([drift_origin(sums.t) for sums in instants])
            change[:, N_GRAVITY:N_FULL, N_FULL:] = -origins[:, None, None] * _IDENTITY[:3, :3]
            turned = change.transpose(0, 2, 1)
            info, rhs = turned @ info @ change, turned @ rhs
        return info, rhs[..., 0]


@dataclass(frozen=True)
class Sums:
    """The normal equations of the 15-state model at one instant: what a solve there needs."""

    info: np.ndarray  # (15, 15) sum H^T H with the drift border
    rhs: np.ndarray  # (15,) sum H^T z
    zz: float  # sum z^T z
    samples: int
    t: float  # s, end of the last sample in


def drift_origin(t: float) -> float:
    """The time origin (s) of the drift in the 15-state solve at t: the middle of the data so far."""
    return 0.5 * t


def _observability(eig: np.ndarray, rank_tolerance: float) -> Observability:
    """Rank and condition number from the ascending eigenvalues of a scaled Gram matrix."""
    low, top = float(eig[0]), max(float(eig[-1]), _TINY)
    rank = int(np.count_nonzero(eig > rank_tolerance * top))
    return Observability(rank, top / low if low > 0 else float("inf"), eig)


def _bias_and_drift(x: np.ndarray, block: np.ndarray, scale: np.ndarray, noise_var: float, t: float
                    ) -> dict[str, np.ndarray]:
    """The bias at t with its sigma and, for 15 states, ``bias_t0`` and the drift rate with theirs.

    Only the bias and drift block of the covariance ``noise_var W^-1`` is formed: ``block`` is that
    block of the scaled inverse, (n - 9) square.
    """
    n = len(x)
    s = scale[N_GRAVITY:]
    sigma = np.sqrt(noise_var * block.diagonal()) * s
    if n == N_FULL:
        return {"bias": x[N_GRAVITY:].copy(), "bias_sigma": sigma}
    cov = noise_var * block * (s[:, None] * s)
    k = x[N_FULL:]
    tau = drift_origin(t)
    offsets = np.array([-tau, t - tau])  # t = 0 and now, from the drift origin
    (b_t0, bias), (b_t0_sigma, bias_sigma) = _bias_at(x[N_GRAVITY:N_FULL], k, cov, offsets)
    return {"bias": bias, "bias_sigma": bias_sigma, "bias_t0": b_t0, "bias_t0_sigma": b_t0_sigma,
            "drift": k.copy(), "drift_sigma": sigma[N_FULL - N_GRAVITY:]}


def _bias_at(b_c: np.ndarray, k: np.ndarray, cov: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``b_c + k dt`` and its 1-sigma, (m, 3) each, at m offsets ``dt`` (s) from the drift origin, from
    the covariance (6, 6) of the centred bias and drift."""
    dt = dt[:, None]
    variance = cov.diagonal()
    var = variance[:3] + 2.0 * dt * cov.diagonal(3) + dt * dt * variance[3:]
    return b_c + k * dt, np.sqrt(np.maximum(var, 0.0))
