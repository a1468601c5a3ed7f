"""The estimator as one object, fed sample by sample live or batch by batch offline.

Per sample: strapdown C_b^ib0 and f^ib0, the 15/12/9-state normal equations and, when the turntable
angles are known, the table-referenced bias. At the solve rate (display rate) it forms a
:class:`Snapshot`: bias (with the ``drift`` bias model also its drift rate) and sigma, observability,
the drift check, and the method-1/method-2 alignment errors against the table attitude together with
the theoretical error of 2019 eq. 8 for the bias at that instant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.estimation.alignment import (
    EarthTurn,
    alignment_matrix,
    attitude_error,
    body_attitude,
    theoretical_error,
)
from hil.estimation.apparent_gravity import (
    N_DRIFT,
    N_FULL,
    N_GRAVITY,
    ApparentGravityEstimator,
    DriftCheck,
    Solution,
    Sums,
)
from hil.estimation.convergence import BIAS_TOLERANCE, DRIFT_TOLERANCE, SolveTrack
from hil.estimation.convergence import convergence_time as settled_from
from hil.estimation.gimbal import as_stacked, gimbal_matrices
from hil.estimation.outlier_gate import accepted
from hil.estimation.strapdown import Strapdown
from hil.estimation.table_reference import TableReferencedBias, TableReferenceEstimator
from hil.frames import Earth, TableGeometry, table_body_rotation
from hil.samples import AlignedBatch, AlignedSample, ImuGap

MAX_SNAPSHOTS = 7200  # 2 h at 1 Hz, ~40 MB; older history is thinned beyond
OUTLIER_SIGMAS = 10.0  # a specific force this many robust sigmas from its neighbours is left out
OUTLIER_WINDOW = 25  # samples before it that it is judged against
OUTLIER_FLOOR = 5e-3  # m/s^2 (~0.5 mg): the gate is never tighter than this (quiet sensors, noise-free data)
BIAS_MODELS = {"constant": N_FULL, "drift": N_DRIFT}  # estimator.bias_model -> states of Snapshot.full
_NAN3 = np.full(3, np.nan)  # a track entry that does not exist (read-only)
_NAN3.setflags(write=False)


@dataclass(frozen=True)
class Snapshot:
    """The estimator's state of knowledge at time ``t`` (SI units)."""

    t: float
    samples: int
    full: Solution  # the bias model's: 12-state (constant) or 15-state (drift); bias at t
    gravity_only: Solution  # 9-state, method 1
    attitude: np.ndarray  # C_b^ib0 at t
    error_method1: np.ndarray | None  # (pitch, roll, yaw) rad against the table, None without angles
    error_method2: np.ndarray | None
    error_theoretical: np.ndarray | None  # (pitch, roll) rad, 2019 eq. 8 with the estimated bias at t
    drift_check: DriftCheck | None = None  # from the 15-state sums whatever the model; None: not observable
    table_bias: np.ndarray | None = None  # the table-referenced bias (3,) of the samples so far; None: not solvable


@dataclass(frozen=True)
class _Instant:
    """A solve instant passed within a batch: the normal equations there and the attitudes at it."""

    sums: Sums
    t: float  # s since t0
    attitude: np.ndarray  # C_b^ib0
    reference: np.ndarray | None  # the table's C_b^n, None without angles
    table_bias: np.ndarray | None = None  # the table-referenced bias then


class OnlineEstimator:
    """Strapdown + apparent-gravity least squares + alignment, with ``update``/``update_many``/``solution``."""

    def __init__(
        self,
        earth: Earth,
        geometry: TableGeometry | None = None,
        solve_period: float = 1.0,
        rank_tolerance: float = 1e-6,
        t0: float = 0.0,
        outlier_sigmas: float | None = OUTLIER_SIGMAS,
        max_snapshots: int = MAX_SNAPSHOTS,
        bias_model: str = "constant",
    ) -> None:
        if bias_model not in BIAS_MODELS:
            raise ValueError(f"bias_model {bias_model!r}: expected one of {', '.join(BIAS_MODELS)}")
        self.bias_model = bias_model
        self.earth = earth
        self.geometry = geometry or TableGeometry()
        self.solve_period = solve_period
        self.t0 = t0  # the start of the first interval: i_b0 and t = 0 of the model
        self.strapdown = Strapdown()
        self.gravity = ApparentGravityEstimator(rank_tolerance)
        self.table = TableReferenceEstimator(earth.f_n, rank_tolerance)
        self.snapshots: list[Snapshot] = []
        self.track = SolveTrack(13)  # every solve: t, bias, its sigma, 15-state drift, its sigma
        self.outlier_sigmas = outlier_sigmas
        self.max_snapshots = max_snapshots
        self.outliers = 0  # specific-force samples left out of the least squares
        self._f_history = np.zeros((0, 3))  # the last OUTLIER_WINDOW specific forces in i_b0
        self._last_dt = 0.0
        self._t_last = t0
        self._angle_history: np.ndarray | None = None  # last two latched angles (2, 3)
        self._next_solve = t0 + solve_period
        self._attitude = np.eye(3)
        self._reference: np.ndarray | None = None  # table attitude C_b^n at the last sample

    @property
    def time(self) -> float:
        """Trial time (s since t0) at the end of the last sample taken."""
        return self._t_last - self.t0

    def update(self, sample: AlignedSample) -> Snapshot | None:
        """Add one sample; returns a new snapshot when a solve instant was passed."""
        before = len(self.snapshots)
        self.update_samples([sample])
        return self.snapshots[-1] if len(self.snapshots) > before else None

    def update_samples(self, samples: list[AlignedSample]) -> None:
        """Add consecutive single samples (the live path) as one batch."""
        self.update_many(AlignedBatch.from_samples(samples, self._t_last))

    def update_many(self, batch: AlignedBatch) -> None:
        """Add consecutive samples, solving at every solve instant they pass.

        The whole batch goes through the strapdown and the measurement model at once; the normal
        equations are summed segment by segment between solve instants.
        """
        n_solves = max(0, math.floor((batch.t[-1] - self._next_solve) / self.solve_period) + 1)
        solve_times = self._next_solve + self.solve_period * np.arange(n_solves)
        # a solve instant that falls in a gap before this batch is served at the batch's first stop
        solve_stops = {max(int(i), 1) for i in np.searchsorted(batch.t, solve_times, side="right")}
        stops = sorted(solve_stops | {len(batch)})
        self._next_solve += n_solves * self.solve_period

        t_end = batch.t - self.t0
        t_start = np.concatenate(([self._t_last - self.t0], t_end[:-1]))
        dt = t_end - t_start
        step = self.strapdown.update_many(batch.dtheta, batch.dv, dt)
        f_ib0 = step.dv_ib0.T / dt[:, None]
        if self._last_dt and dt[0] > 1.5 * self._last_dt:
            self._f_history = self._f_history[:0]  # data gap: judge afresh
        self._last_dt = float(dt[-1])
        accept = self._accept(f_ib0)
        table = None
        if batch.has_angles:
            mean_attitude, attitude = self._table_attitudes(batch.angles)
            table = self.table.update_segments(0.5 * (t_start + t_end), batch.dv / dt[:, None], mean_attitude, stops,
                                               accept)
            references = as_stacked(attitude[..., np.array(stops) - 1])  # (stops, 3, 3)
        instants: list[_Instant] = []  # solved together after the batch
        c_mean = step.c_mean.transpose(2, 0, 1)  # (N, 3, 3), as the measurement matrix takes it
        for k, stop in enumerate(self.gravity.update_segments(t_start, t_end, f_ib0, c_mean, stops, accept)):
            if table is not None:
                next(table)
                self._reference = references[k]
            self._attitude = step.c_end[..., stop - 1]
            self._t_last = float(batch.t[stop - 1])
            if stop in solve_stops:
                instants.append(self._instant())
        for snap in self._snapshots(instants):
            self._keep(snap)

    def bridge(self, gap: ImuGap) -> bool:
        """Carry the attitude across lost IMU samples with the table: the body rotation over the gap is
        ``C_n^b(t1) C_n(t2)^n(t1) C_b^n(t2)`` (gimbal angles at both ends plus the earth's turn). No
        measurement is taken from the gap. False when the table angles are missing at either end: the
        attitude is then held, and the estimate degrades by the rotation the gap hid."""
        known = gap.known
        if known:
            self.strapdown.carry(table_body_rotation(self.geometry, self.earth, gap.t_end - gap.t_start,
                                                     gap.angles_start, gap.angles_end)[0])
        else:
            self.strapdown.carry(np.eye(3))
        self._attitude = self.strapdown.attitude
        self._angle_history = None
        self._f_history = self._f_history[:0]
        self._t_last = gap.t_end
        return known

    def solution(self) -> Snapshot:
        """The solution with everything received so far; nothing is kept (:meth:`finish` keeps it)."""
        if self.snapshots and self.snapshots[-1].samples == self.gravity.samples:
            return self.snapshots[-1]
        return self._snapshots([self._instant()], tracked=False)[0]

    def finish(self) -> Snapshot:
        """End of data: keep the solution with everything received as the last snapshot and in the track;
        returns it."""
        if not self.snapshots or self.snapshots[-1].samples != self.gravity.samples:
            self._keep(self._snapshots([self._instant()])[0])
        return self.snapshots[-1]

    def table_referenced(self) -> TableReferencedBias:
        return self.table.solve()

    def bias_converged_at(self, tolerance: float = BIAS_TOLERANCE) -> float | None:
        """Convergence time (s) of the bias (:mod:`hil.estimation.convergence`, tolerance in m/s^2) over
        every solve so far."""
        rows = self.track.rows
        return settled_from(rows[:, 0], rows[:, 1:4], rows[:, 4:7], tolerance)

    def drift_converged_at(self, tolerance: float = DRIFT_TOLERANCE) -> float | None:
        """Convergence time (s) of the 15-state drift rate (tolerance in m/s^3) over every solve so far."""
        rows = self.track.rows
        return settled_from(rows[:, 0], rows[:, 7:10], rows[:, 10:13], tolerance)

    def _keep(self, snap: Snapshot) -> None:
        """Append a snapshot; past ``max_snapshots`` every other older one is dropped, so a 24-hour
        trial's history stays bounded (full display rate for the first ``max_snapshots``, then thinner)."""
        self.snapshots.append(snap)
        if len(self.snapshots) > self.max_snapshots:
            self.snapshots = [*self.snapshots[:-1:2], snap]

    def _accept(self, f_ib0: np.ndarray) -> np.ndarray | None:
        """False for a specific force that jumps away from the median of the previous ``OUTLIER_WINDOW``
        by more than ``outlier_sigmas`` robust sigmas (their MAD) on any axis: a frame whose damage the
        checksum missed. f^ib0 moves by ~1e-5 m/s^2 per sample (earth rate, the bias turning with the
        swing), far below the noise, so the median of the last few is a model-free prediction."""
        if self.outlier_sigmas is None:
            return None
        history = self._f_history
        series = np.vstack((history, f_ib0))
        self._f_history = series[-OUTLIER_WINDOW:]
        first = max(0, OUTLIER_WINDOW - len(history))  # the samples before it have no full window yet
        accept = np.ones(len(f_ib0), dtype=bool)
        if first < len(f_ib0):
            start = len(history) + first - OUTLIER_WINDOW
            accept[first:] = accepted(series[start:], OUTLIER_WINDOW, self.outlier_sigmas, OUTLIER_FLOOR)
        self.outliers += int(len(accept) - accept.sum())
        return accept

    def _table_attitudes(self, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """C_b^n over each interval (mean, by Simpson's rule) and at its end, each (3, 3, N) component-major,
        from the latched angles.

        The mid-interval angles come from the quadratic through the last three latched angles
        (weights -1/8, 3/4, 3/8).
        """
        history = self._angle_history if self._angle_history is not None else np.vstack((angles[0], angles[0]))
        series = np.vstack((history, angles))
        if (np.abs(np.diff(series, axis=0)) >= np.pi).any():  # else np.unwrap would return them unchanged
            series = np.unwrap(series, axis=0)
        mid = -0.125 * series[:-2] + 0.75 * series[1:-1] + 0.375 * series[2:]
        n = len(series) - 1
        c = gimbal_matrices(self.geometry, np.vstack((series[1:], mid)))[0]
        c_end, c_mid = c[..., :n], c[..., n:]
        self._angle_history = series[-2:]
        return (c_end[..., :-1] + 4.0 * c_mid + c_end[..., 1:]) / 6.0, c_end[..., 1:]

    def _instant(self) -> _Instant:
        """What a snapshot now needs: the normal equations, the time, the attitudes and the table-referenced bias."""
        return _Instant(self.gravity.sums(), self._t_last - self.t0, self._attitude.copy(), self._reference,
                        self.table.solve().bias)

    def _snapshots(self, instants: list[_Instant], tracked: bool = True) -> list[Snapshot]:
        """The snapshots at these instants, their least squares solved and their alignments formed as stacks;
        each solve added to :attr:`track` when ``tracked``."""
        if not instants:
            return []
        models = (N_DRIFT, N_GRAVITY) if BIAS_MODELS[self.bias_model] == N_DRIFT else (N_DRIFT, N_FULL, N_GRAVITY)
        solved = self.gravity.solve_many([i.sums for i in instants], models)
        solutions = [(s[0], *s) if len(s) == 2 else s for s in solved]  # (drift, full, gravity_only)
        errors = self._alignment_errors(instants, solutions)
        snapshots = []
        for instant, (drift, full, gravity_only), errs in zip(instants, solutions, errors):
            if tracked:
                self.track.append(np.concatenate((
                    [instant.t],
                    *(_NAN3 if v is None else v for v in (full.bias, full.bias_sigma, drift.drift, drift.drift_sigma)),
                )))  # fmt: skip
            snapshots.append(Snapshot(instant.t, instant.sums.samples, full, gravity_only, instant.attitude, *errs,
                                      drift_check=DriftCheck.from_solution(drift), table_bias=instant.table_bias))
        return snapshots

    def _alignment_errors(self, instants: list[_Instant], solutions: list[list[Solution]]
                          ) -> list[list[np.ndarray | None]]:
        """Per instant: the method-1 and method-2 attitude errors against the table, and the theoretical error
        of the bias (2019 eq. 8); None without table angles (or at t = 0, or for an unobservable bias)."""
        errors: list[list[np.ndarray | None]] = [[None, None, None] for _ in instants]
        rows = [k for k, instant in enumerate(instants) if instant.reference is not None and instant.t > 0]
        if not rows:
            return errors
        turn = EarthTurn.at(np.array([instants[k].t for k in rows]), self.earth)
        reference = np.array([instants[k].reference for k in rows])
        attitude = np.array([instants[k].attitude for k in rows])
        for method in (0, 1):  # the 9-state solution (method 1), the bias model's (method 2)
            a_internal = np.array([solutions[k][2 - method].a_internal for k in rows])
            gravity = turn.apparent_gravity(a_internal)
            c_ib0_n0 = alignment_matrix(gravity[:, 0], gravity[:, 1], turn)
            for k, error in zip(rows, attitude_error(body_attitude(c_ib0_n0, attitude, turn), reference)):
                errors[k][method] = error
        biased = [j for j, k in enumerate(rows) if solutions[k][1].bias is not None]  # positions in rows
        if biased:
            bias = np.array([solutions[rows[j]][1].bias for j in biased])
            for j, error in zip(biased, theoretical_error(bias, reference[biased], self.earth.g)):
                errors[rows[j]][2] = error
        return errors


def convergence_time(snapshots: list[Snapshot]) -> float | None:
    """Convergence time (s) of the bias over these snapshots (:mod:`hil.estimation.convergence`).

    On the estimator's own history prefer :meth:`OnlineEstimator.bias_converged_at`, which sees every
    solve where the history beyond ``max_snapshots`` is thinned.
    """
    bias = np.array([_NAN3 if s.full.bias is None else s.full.bias for s in snapshots]).reshape(-1, 3)
    sigma = np.array([_NAN3 if s.full.bias_sigma is None else s.full.bias_sigma for s in snapshots]).reshape(-1, 3)
    return settled_from(np.array([s.t for s in snapshots]), bias, sigma, BIAS_TOLERANCE)
