"""Sync alignment: IMU and turntable samples paired by their sync pulse count on one time line.

Both devices count the same external pulse train, so a sample's time is its count over the train's
rate plus its latch delay:

- IMU sample k describes the increments over ``(t_k - 1/rate, t_k]`` with ``t_k = k / rate + delay``;
- the table sample with counter c holds the gimbal angles at ``tau = c / rate + latch_delay`` (a table
  that latches every n-th pulse counts in steps of n).

The aligner places the unwrapped gimbal angles at every IMU instant by cubic Lagrange
interpolation on the four table samples that end at the first one at or after the instant (the
instant lies within the last knot interval, where the error is ~1e-13 rad for a 10 deg/s swing at
200 Hz). It releases IMU samples in count order and copes with

- duplicates (dropped, counted) and out-of-order frames (reordered within ``reorder_window``);
- IMU gaps: up to ``max_fill`` missing samples are filled from the cubic through the cumulative
  increments around the gap (counted); longer gaps become an :class:`~hil.samples.ImuGap` that the
  estimator bridges with the table attitude;
- table gaps: interpolated across up to ``max_angle_gap_s``; beyond that the IMU samples go out
  without angles (counted).

Decisions depend only on the order in which samples arrive, never on wall-clock time, so a
replay of the same frames gives bit-identical output.

Fallback for devices without a sync input (``free_running``): each counter is mapped to host time by
an :class:`~hil.pipeline.clock_model.AffineClock` fitted to the receive times, and the table's latch instants are
placed on the IMU's time line through both fits (accuracy set by the host's receive-time jitter).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from hil.pipeline.clock_model import AffineClock
from hil.samples import AlignedSample, ImuGap, ImuSample, TableSample

Vec3 = tuple[float, float, float]


def lagrange_weights(x: float, knots: list[float]) -> list[float]:
    """Weights w_j with ``p(x) = sum w_j y_j`` for the polynomial through (knots, y)."""
    weights = []
    for j, xj in enumerate(knots):
        w = 1.0
        for m, xm in enumerate(knots):
            if m != j:
                w *= (x - xm) / (xj - xm)
        weights.append(w)
    return weights


@dataclass
class AlignerCounters:
    """What the aligner did, for the result's ``streams`` block."""

    aligned: int = 0  # samples released to the estimator
    imu_duplicates: int = 0
    table_duplicates: int = 0
    imu_late: int = 0  # IMU frames that arrived after their slot had been filled or bridged
    imu_filled: int = 0  # missing IMU samples filled by interpolation
    imu_bridged: int = 0  # missing IMU samples inside gaps bridged with the table attitude
    imu_gaps: int = 0  # gaps of the IMU count (filled or bridged)
    without_angles: int = 0  # samples released without table angles (table gap or table silent)
    table_unmapped: int = 0  # free-running: table samples before the IMU's clock was known

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class _TableKnots:
    """Table samples sorted by count, with angles unwrapped against their neighbours."""

    index: list[int] = field(default_factory=list)
    time: list[float] = field(default_factory=list)
    angles: list[np.ndarray] = field(default_factory=list)

    def insert(self, index: int, time: float, angles: np.ndarray) -> bool:
        """Add a sample; False if its count is already present."""
        i = bisect.bisect_left(self.index, index)
        if i < len(self.index) and self.index[i] == index:
            return False
        if self.angles:
            ref = self.angles[i - 1] if i > 0 else self.angles[0]
            angles = ref + (angles - ref + math.pi) % (2.0 * math.pi) - math.pi
        self.index.insert(i, index)
        self.time.insert(i, time)
        self.angles.insert(i, angles)
        return True

    def ready(self, t: float) -> bool:
        """True when the knots :meth:`at` uses for ``t`` have all arrived."""
        i = bisect.bisect_left(self.time, t)
        return i < len(self.time) and max(0, i - 3) + 4 <= len(self.time)

    def last_time(self) -> float:
        return self.time[-1] if self.time else -math.inf

    def forget_before(self, t: float, keep: int = 4) -> None:
        """Drop knots no longer needed for instants at or after ``t``."""
        i = max(0, bisect.bisect_left(self.time, t) - keep)
        if i:
            del self.index[:i], self.time[:i], self.angles[:i]

    def at(self, t: float, max_gap: float) -> Vec3 | None:
        """Angles at ``t`` from the cubic on the 4 knots ending at the first knot >= t (the first four at
        the start); None across a gap longer than ``max_gap`` or beyond the last knot."""
        i = bisect.bisect_left(self.time, t)
        if i == len(self.time) or (i > 0 and self.time[i] - self.time[i - 1] > max_gap):
            return None
        if i == 0 and self.time[0] - t > max_gap:
            return None
        lo = max(0, i - 3)
        hi = min(len(self.time), lo + 4)
        weights = lagrange_weights(t, self.time[lo:hi])
        value = sum(w * a for w, a in zip(weights, self.angles[lo:hi]))
        return tuple(value.tolist())


class Aligner:
    """Pairs IMU and table samples by sync count and yields :class:`AlignedSample` / :class:`ImuGap` in order.

    ``imu_rate_hz`` and ``table_counter_rate_hz`` are the counters' rates: both the pulse train's when
    the table is synchronised (a table latching every fifth pulse of 1000 Hz counts 5, 10, 15 ...), the
    table's own latch rate when it is free-running. ``table_wait`` (s) is how far the IMU may run ahead
    of a silent table before its samples go out without angles; ``with_table`` False aligns the IMU alone.
    """

    def __init__(self, imu_rate_hz: float, table_counter_rate_hz: float, imu_delay_s: float = 0.0, *,
                 with_table: bool = True, max_fill: int = 10, reorder_window: int = 4,
                 max_angle_gap_s: float = 0.1, table_wait_s: float = 5.0, free_running: bool = False) -> None:
        self.imu_period = 1.0 / imu_rate_hz
        self.table_count_period = 1.0 / table_counter_rate_hz
        self.imu_delay = imu_delay_s
        self.with_table = with_table
        self.max_fill = max_fill
        self.reorder_window = reorder_window
        self.max_angle_gap = max_angle_gap_s
        self.table_wait = table_wait_s
        self.counters = AlignerCounters()
        self._pending: dict[int, ImuSample] = {}
        self._next: int | None = None  # count of the next IMU sample to release
        self._first = 0  # count of the first IMU sample
        self._history: list[tuple[int, np.ndarray, np.ndarray]] = []  # last released (count, dtheta, dv)
        self._table = _TableKnots()
        self._out: list[AlignedSample | ImuGap] = []
        self._last_angles: Vec3 | None = None
        self.clocks = (AffineClock(imu_rate_hz), AffineClock(table_counter_rate_hz)) if free_running else None

    def imu_time(self, index: int) -> float:
        return index * self.imu_period + self.imu_delay

    @property
    def t0(self) -> float | None:
        """Start of the first IMU interval (the estimator's i_b0 instant); None before any IMU sample."""
        return None if self._next is None else self.imu_time(self._first) - self.imu_period

    def add_imu(self, sample: ImuSample) -> list[AlignedSample | ImuGap]:
        """Take one IMU sample; returns what became ready."""
        k = sample.sync_index
        if self.clocks is not None:
            self.clocks[0].add(k, sample.host_time)
        if self._next is None:
            self._next = self._first = k
        if k < self._next:
            self.counters.imu_late += 1
        elif k in self._pending:
            self.counters.imu_duplicates += 1
        else:
            self._pending[k] = sample
        return self._release()

    def add_table(self, sample: TableSample) -> list[AlignedSample | ImuGap]:
        """Take one table sample; returns what became ready."""
        t = sample.sync_index * self.table_count_period + sample.latch_delay
        if self.clocks is not None:
            imu, table = self.clocks
            table.add(sample.sync_index, sample.host_time)
            if not imu.ready:
                self.counters.table_unmapped += 1
                return self._release()
            # the table's latch instant on the host clock, then as an IMU count, then on the IMU time line
            host = table.time(sample.sync_index) + sample.latch_delay
            t = (host - imu.time(0)) / imu.period * self.imu_period
        if not self._table.insert(sample.sync_index, t, np.asarray(sample.angles, dtype=float)):
            self.counters.table_duplicates += 1
        return self._release()

    def flush(self) -> list[AlignedSample | ImuGap]:
        """End of the trial: release everything still waiting (angles where the table allows)."""
        while self._pending:
            self._release(final=True)
            if self._pending and self._next not in self._pending:
                self._close_gap(min(self._pending))
        return self._take()

    # -- internals -------------------------------------------------------------------------------

    def _take(self) -> list[AlignedSample | ImuGap]:
        out, self._out = self._out, []
        return out

    def _release(self, final: bool = False) -> list[AlignedSample | ImuGap]:
        while self._pending:
            k = self._next
            if k not in self._pending:
                newest, resume = max(self._pending), min(self._pending)
                if (newest - k < self.reorder_window or newest == resume) and not final:
                    break  # k may still arrive out of order; the fill needs the sample after the resume
                if self.with_table and not final and not self._table_ready(self.imu_time(resume) - self.imu_period):
                    break  # the bridge needs the table angles at the gap's end
                self._close_gap(min(self._pending))
                continue
            t = self.imu_time(k)
            angles = None
            if self.with_table:
                if not final and not self._table_ready(t):
                    break  # the table sample for this instant is still on its way
                angles = self._table.at(t, self.max_angle_gap)
                if angles is None:
                    self.counters.without_angles += 1
            self._emit(k, self._pending.pop(k), t, angles)
        if self.with_table and self._next is not None:
            self._table.forget_before(self.imu_time(self._next))
        return self._take() if not final else []

    def _table_ready(self, t: float) -> bool:
        """The table samples around ``t`` have arrived, or the table is so far behind the IMU (more
        than ``table_wait``) that the IMU goes on without it."""
        if self._table.ready(t):
            return True
        ahead = self.imu_time(max(self._pending)) - max(self._table.last_time(), t)
        return ahead >= self.table_wait

    def _emit(self, k: int, sample: ImuSample, t: float, angles: Vec3 | None) -> None:
        self._out.append(AlignedSample(t, sample.dtheta, sample.dv, angles))
        self._history = [*self._history[-1:], (k, np.asarray(sample.dtheta), np.asarray(sample.dv))]
        self._last_angles = angles
        self.counters.aligned += 1
        self._next = k + 1

    def _close_gap(self, resume: int) -> None:
        """Samples ``_next .. resume - 1`` are lost: fill them if short and surrounded, else bridge."""
        start = self._next
        missing = resume - start
        self.counters.imu_gaps += 1
        after = [self._pending.get(resume), self._pending.get(resume + 1)]
        if missing <= self.max_fill and len(self._history) == 2 and all(s is not None for s in after):
            self.counters.imu_filled += missing
            for k, dtheta, dv in self._fill(start, resume, after):
                self._emit(k, ImuSample(k, dtheta, dv), self.imu_time(k), self._angles_at(self.imu_time(k)))
            return
        self.counters.imu_bridged += missing
        t_start, t_end = self.imu_time(start) - self.imu_period, self.imu_time(resume) - self.imu_period
        end_angles = self._angles_at(t_end)
        self._out.append(ImuGap(t_start, t_end, self._last_angles, end_angles))
        self._history = []
        self._last_angles = end_angles
        self._next = resume

    def _angles_at(self, t: float) -> Vec3 | None:
        return self._table.at(t, self.max_angle_gap) if self.with_table else None

    def _fill(self, start: int, resume: int, after: list[ImuSample]) -> list[tuple[int, Vec3, Vec3]]:
        """Increments of the missing samples from the cubic through the cumulative sums around the gap."""
        (k1, th1, v1), (k2, th2, v2) = self._history
        known = (float(k1 - 1), float(k1), float(k2))
        th = cumulative_cubic(known, (np.zeros(3), th1, th1 + th2), float(resume),
                              (np.asarray(after[0].dtheta), np.asarray(after[1].dtheta)))
        v = cumulative_cubic(known, (np.zeros(3), v1, v1 + v2), float(resume),
                             (np.asarray(after[0].dv), np.asarray(after[1].dv)))
        return [(k, tuple((th(k) - th(k - 1)).tolist()), tuple((v(k) - v(k - 1)).tolist()))
                for k in range(start, resume)]


def cumulative_cubic(x_known, y_known, x_resume: float, increments_after):
    """The cubic Y(x) of a cumulative increment across a gap, as a function of the sample count x.

    Y is known at the ends of the samples before the gap (``x_known``, ``y_known``); after it only
    the increments over (x_resume - 1, x_resume] and (x_resume, x_resume + 1] are known, since the
    gap's own total was lost. Five conditions on four coefficients, solved by least squares (exact
    when the cumulative curve is a cubic, i.e. a quadratic rate).
    """
    x0 = x_known[-1]

    def powers(x: float) -> np.ndarray:
        return np.array([1.0, x - x0, (x - x0) ** 2, (x - x0) ** 3])

    rows = [powers(x) for x in x_known]
    rows += [powers(x_resume + m) - powers(x_resume + m - 1) for m in (0, 1)]
    rhs = np.vstack((*y_known, *increments_after))
    coef, *_ = np.linalg.lstsq(np.array(rows), rhs, rcond=None)
    return lambda x: powers(x) @ coef
