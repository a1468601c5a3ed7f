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

- duplicates (dropped, counted) and out-of-order frames (reordered within ``REORDER_WINDOW``);
- IMU gaps: up to ``MAX_FILL`` missing samples are filled from the cubic through the cumulative
  increments around the gap (counted) when the samples around it are valid (not flagged by the device);
  longer gaps, or those beside a flagged sample, become an :class:`~hil.samples.ImuGap` that the
  estimator bridges with the table attitude;
- table gaps: interpolated across up to ``MAX_ANGLE_GAP_S``; beyond that the IMU samples go out
  without angles (counted).

Samples come in as the arrays of one read (:class:`~hil.samples.ImuSamples`, :class:`~hil.samples.TableSamples`)
and go out as runs of consecutive aligned samples (:class:`~hil.samples.AlignedBatch`, NaN angles where
a sample has none) and gaps: the interpolation and the release work on whole runs. Decisions depend
only on the order in which reads arrive, never on wall-clock time, so a replay of the same frames
gives bit-identical output.

Fallback for devices without a sync input (``free_running``): each counter is mapped to host time by
an :class:`~hil.pipeline.clock_model.AffineClock` fitted to the receive times, and the table's latch instants are
placed on the IMU's time line through both fits (accuracy set by the host's receive-time jitter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.pipeline.clock_model import AffineClock
from hil.samples import NO_ANGLES, AlignedBatch, ImuGap, ImuSample, ImuSamples, TableSample, TableSamples

MAX_FILL = 10  # IMU samples a gap may lack and still be filled
REORDER_WINDOW = 4  # IMU samples a frame may arrive out of order and still be put in place
MAX_ANGLE_GAP_S = 0.1  # s of table data the angles are interpolated across

Vec3 = tuple[float, float, float]
Released = AlignedBatch | ImuGap


def lagrange_weights(x, knots) -> np.ndarray:
    """Weights w_j with ``p(x) = sum_j w_j y_j`` for the polynomial through (knots, y): (m,) for a number ``x``
    and knots (m,), (N, m) for ``x`` (N,) and knots (N, m). ``w_j = prod_{i != j} (x - x_i) / (x_j - x_i)``,
    its factors multiplied in the order of i, for all j at once."""
    knots = np.asarray(knots, dtype=float)
    m = knots.shape[-1]
    diagonal = np.eye(m, dtype=bool)
    ratio = (np.asarray(x, dtype=float)[..., None, None] - knots[..., None, :]) / (
        knots[..., :, None] - knots[..., None, :] + diagonal)  # [..., j, i]; 1 on the diagonal, never read
    ratio[..., diagonal] = 1.0  # w_j has no factor for i = j: times 1.0, exactly
    weights = np.ones(ratio.shape[:-1])
    for i in range(m):
        weights *= ratio[..., i]
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
    after_table_end: int = 0  # at the end, samples after the table's last angles: not released

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


def _whole_turns(reference: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """The whole turns that bring ``angles`` nearest ``reference`` (rad, elementwise)."""
    return np.round((reference - angles) / (2.0 * math.pi))


class _TableKnots:
    """Table samples sorted by count, with their angles unwrapped: each is moved by the whole turns that bring
    it nearest the sample before it (the first one nearest the first), counted from the angles as received."""

    def __init__(self) -> None:
        self.index = np.zeros(0, dtype=np.int64)
        self.time = np.zeros(0)
        self._received = np.zeros((0, 3))  # the angles as received, rad
        self._turns = np.zeros((0, 3))  # whole turns added to them

    @property
    def angles(self) -> np.ndarray:
        """The unwrapped angles (n, 3), rad."""
        return self._received + 2.0 * math.pi * self._turns

    def insert(self, index: np.ndarray, time: np.ndarray, angles: np.ndarray) -> int:
        """Add samples: counts (m,), times (m,) and angles (m, 3); returns how many were already present
        (dropped). Samples in order after the last are added at once, others one by one."""
        if not len(index):
            return 0
        if (not len(self.index) or index[0] > self.index[-1]) and (np.diff(index) > 0).all():
            received = np.vstack((self._received[-1:], angles))
            steps = _whole_turns(received[:-1], received[1:])
            turns = np.cumsum(np.vstack((self._turns[-1:] if len(self.index) else np.zeros((1, 3)), steps)), axis=0)
            self._add(len(self.index), index, time, angles, turns[-len(index):])
            return 0
        duplicates = 0
        for k, t, a in zip(index.tolist(), time.tolist(), angles, strict=True):
            i = int(np.searchsorted(self.index, k))
            if i < len(self.index) and self.index[i] == k:
                duplicates += 1
                continue
            ref = i - 1 if i > 0 else 0
            turns = self._turns[ref] + _whole_turns(self._received[ref], a) if len(self.index) else np.zeros(3)
            self._add(i, np.array([k]), np.array([t]), a[None], turns[None])
        return duplicates

    def _add(self, i: int, index: np.ndarray, time: np.ndarray, received: np.ndarray, turns: np.ndarray) -> None:
        """Put samples in before position i."""
        def put(old: np.ndarray, new: np.ndarray) -> np.ndarray:
            return np.concatenate((old[:i], new, old[i:]))

        self.index, self.time = put(self.index, index), put(self.time, time)
        self._received, self._turns = put(self._received, received), put(self._turns, turns)

    def ready(self, t: np.ndarray) -> np.ndarray:
        """Per instant, True when the knots :meth:`at` uses for it have all arrived."""
        i = np.searchsorted(self.time, t, side="left")
        return (i < len(self.time)) & (len(self.time) >= 4)

    def last_time(self) -> float:
        return float(self.time[-1]) if len(self.time) else -math.inf

    def forget_before(self, t: float, keep: int = 4) -> None:
        """Drop knots no longer needed for instants at or after ``t``."""
        i = max(0, int(np.searchsorted(self.time, t, side="left")) - keep)
        if i:
            self.index, self.time = self.index[i:], self.time[i:]
            self._received, self._turns = self._received[i:], self._turns[i:]

    def at(self, t: np.ndarray, max_gap: float) -> np.ndarray:
        """Angles (N, 3) at instants ``t`` (N,) from the cubic on the 4 knots ending at the first knot >= t
        (the first four at the start); NaN across a gap longer than ``max_gap`` or beyond the last knot."""
        out = np.full((len(t), 3), np.nan)
        time = self.time
        if not len(time) or not len(t):
            return out
        i = np.searchsorted(time, t, side="left")
        inside = i < len(time)
        ic = np.minimum(i, len(time) - 1)
        spans = np.where(i > 0, time[ic] - time[np.maximum(ic - 1, 0)], time[0] - t)
        ok = inside & ~(spans > max_gap)
        if not ok.any():
            return out
        lo = np.maximum(0, i[ok] - 3)[:, None] + np.arange(min(len(time), 4))  # at the start, the first 4
        weights = lagrange_weights(t[ok], time[lo])
        knots = self.angles[lo]
        value = 0
        for j in range(lo.shape[1]):
            value = value + weights[:, j, None] * knots[:, j]
        out[ok] = value
        return out


class Aligner:
    """Pairs IMU and table samples by sync count and releases runs of aligned samples and gaps in order.

    ``imu_rate_hz`` and ``table_counter_rate_hz`` are the counters' rates: both the pulse train's when
    the table is synchronised (a table latching every fifth pulse of 1000 Hz counts 5, 10, 15 ...), the
    table's own latch rate when it is free-running. ``table_wait`` (s) is how far the IMU may run ahead
    of a silent table before its samples go out without angles; ``with_table`` False aligns the IMU alone.
    """

    def __init__(self, imu_rate_hz: float, table_counter_rate_hz: float, imu_delay_s: float = 0.0, *,
                 with_table: bool = True, table_wait_s: float = 5.0, free_running: bool = False) -> None:
        self.imu_period = 1.0 / imu_rate_hz
        self.table_count_period = 1.0 / table_counter_rate_hz
        self.imu_delay = imu_delay_s
        self.with_table = with_table
        self.table_wait = table_wait_s
        self.counters = AlignerCounters()
        # pending IMU samples, sorted by count
        self._count = np.zeros(0, dtype=np.int64)
        self._dtheta = np.zeros((0, 3))
        self._dv = np.zeros((0, 3))
        self._valid = np.zeros(0, dtype=bool)  # the device marked the sample valid
        self._next: int | None = None  # count of the next IMU sample to release
        self._first = 0  # count of the first IMU sample
        self._history: list[tuple[int, np.ndarray, np.ndarray, bool]] = []  # last released (count, dtheta, dv, valid)
        self._table = _TableKnots()
        self._out: list[Released] = []
        self._last_angles: Vec3 = NO_ANGLES
        self.clocks = (AffineClock(imu_rate_hz), AffineClock(table_counter_rate_hz)) if free_running else None

    def imu_time(self, index):
        return index * self.imu_period + self.imu_delay

    @property
    def t0(self) -> float | None:
        """Start of the first IMU interval (the estimator's i_b0 instant); None before any IMU sample."""
        return None if self._next is None else self.imu_time(self._first) - self.imu_period

    def add_imu(self, sample: ImuSample) -> list[Released]:
        """:meth:`add_imus` of one sample."""
        return self.add_imus(ImuSamples.stack([sample]))

    def add_table(self, sample: TableSample) -> list[Released]:
        """:meth:`add_tables` of one sample."""
        return self.add_tables(TableSamples.stack([sample]))

    def add_imus(self, samples: ImuSamples) -> list[Released]:
        """Take the IMU samples of one read; returns what became ready."""
        if not len(samples):
            return self._release()
        k = samples.sync_index
        if self.clocks is not None:
            for count, host_time in zip(k.tolist(), samples.host_time.tolist(), strict=True):
                self.clocks[0].add(count, host_time)
        if self._next is None:
            self._next = self._first = int(k[0])
        after = self._count[-1] if len(self._count) else self._next - 1
        if k[0] > after and (len(k) == 1 or (np.diff(k) > 0).all()):  # in order: all new, after those pending
            self._count = np.concatenate((self._count, k))
            self._dtheta = np.concatenate((self._dtheta, samples.dtheta))
            self._dv = np.concatenate((self._dv, samples.dv))
            self._valid = np.concatenate((self._valid, samples.valid))
            return self._release()
        late = k < self._next
        self.counters.imu_late += int(np.count_nonzero(late))
        _, first = np.unique(k, return_index=True)
        new = np.zeros(len(k), dtype=bool)
        new[first] = True  # the first of repeats within the read
        new &= ~late & ~np.isin(k, self._count)
        self.counters.imu_duplicates += int(np.count_nonzero(~late & ~new))
        count = np.concatenate((self._count, k[new]))
        order = np.argsort(count, kind="stable")
        self._count = count[order]
        self._dtheta = np.concatenate((self._dtheta, samples.dtheta[new]))[order]
        self._dv = np.concatenate((self._dv, samples.dv[new]))[order]
        self._valid = np.concatenate((self._valid, samples.valid[new]))[order]
        return self._release()

    def add_tables(self, samples: TableSamples) -> list[Released]:
        """Take the table samples of one read; returns what became ready."""
        times = samples.sync_index * self.table_count_period + samples.latch_delay
        mapped = np.ones(len(times), dtype=bool)
        if self.clocks is not None:
            imu, table = self.clocks
            for j, (count, delay, host_time) in enumerate(zip(samples.sync_index.tolist(), samples.latch_delay.tolist(),
                                                              samples.host_time.tolist(), strict=True)):
                table.add(count, host_time)
                if not imu.ready:
                    mapped[j] = False
                    continue
                # the table's latch instant on the host clock, then as an IMU count, then on the IMU time line
                host = table.time(count) + delay
                times[j] = (host - imu.time(0)) / imu.period * self.imu_period
            self.counters.table_unmapped += int(np.count_nonzero(~mapped))
        self.counters.table_duplicates += self._table.insert(samples.sync_index[mapped], times[mapped],
                                                             samples.angles[mapped])
        return self._release()

    def flush(self) -> list[Released]:
        """End of the trial: release everything still waiting (angles where the table allows) but the samples
        after the table's last angles (the table's last frames were still on their way): they are counted."""
        if self.with_table and len(self._table.time) and len(self._count):
            keep = int(np.searchsorted(self.imu_time(self._count), self._table.last_time(), side="right"))
            self.counters.after_table_end += len(self._count) - keep
            self._count, self._dtheta, self._dv = self._count[:keep], self._dtheta[:keep], self._dv[:keep]
            self._valid = self._valid[:keep]
        self._release(final=True)
        return self._take()

    # -- internals -------------------------------------------------------------------------------

    def _take(self) -> list[Released]:
        out, self._out = self._out, []
        return out

    def _release(self, final: bool = False) -> list[Released]:
        while len(self._count):
            k = self._next
            if self._count[0] != k:
                newest, resume = int(self._count[-1]), int(self._count[0])
                if (newest - k < REORDER_WINDOW or newest == resume) and not final:
                    break  # k may still arrive out of order; the fill needs the sample after the resume
                if self.with_table and not final and not self._table_ready(np.array([self.imu_time(resume)
                                                                                     - self.imu_period]))[0]:
                    break  # the bridge needs the table angles at the gap's end
                self._close_gap(resume)
                continue
            run = int(np.argmax(self._count - k != np.arange(len(self._count)))) or len(self._count)
            t = self.imu_time(self._count[:run])
            if self.with_table and not final:
                ready = self._table_ready(t)  # the table samples for these instants have arrived
                run = int(np.argmin(ready)) if not ready.all() else run
                t = t[:run]
                if not run:
                    break
            angles = self._angles_at(t)
            self.counters.without_angles += int(np.count_nonzero(np.isnan(angles[:, 0]))) if self.with_table else 0
            self._emit(self._count[:run], t, self._dtheta[:run], self._dv[:run], angles, self._valid[:run])
            self._count, self._dtheta, self._dv = self._count[run:], self._dtheta[run:], self._dv[run:]
            self._valid = self._valid[run:]
        if self.with_table and self._next is not None:
            self._table.forget_before(self.imu_time(self._next))
        return self._take() if not final else []

    def _table_ready(self, t: np.ndarray) -> np.ndarray:
        """Per instant, whether the table samples around it have arrived, or the table is so far behind
        the IMU (more than ``table_wait``) that the IMU goes on without it."""
        ahead = self.imu_time(int(self._count[-1])) - np.maximum(self._table.last_time(), t)
        return self._table.ready(t) | (ahead >= self.table_wait)

    def _emit(self, k: np.ndarray, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, angles: np.ndarray,
              valid: np.ndarray) -> None:
        self._out.append(AlignedBatch(t, dtheta, dv, angles, valid=None if valid.all() else valid))
        last = [(int(k[j]), dtheta[j], dv[j], bool(valid[j])) for j in range(max(0, len(k) - 2), len(k))]
        self._history = [*self._history, *last][-2:]
        self._last_angles = tuple(angles[-1].tolist())
        self.counters.aligned += len(k)
        self._next = int(k[-1]) + 1

    def _close_gap(self, resume: int) -> None:
        """Samples ``_next .. resume - 1`` are lost: fill them if short and surrounded, else bridge."""
        start = self._next
        missing = resume - start
        self.counters.imu_gaps += 1
        following = len(self._count) > 1 and self._count[1] == resume + 1
        valid_around = following and all(h[3] for h in self._history) and self._valid[:2].all()
        if missing <= MAX_FILL and len(self._history) == 2 and valid_around:
            self.counters.imu_filled += missing
            k = np.arange(start, resume)
            dtheta, dv = self._fill(start, resume)
            t = self.imu_time(k)
            self._emit(k, t, dtheta, dv, self._angles_at(t), np.ones(len(k), dtype=bool))
            return
        self.counters.imu_bridged += missing
        t_start, t_end = self.imu_time(start) - self.imu_period, self.imu_time(resume) - self.imu_period
        end_angles = tuple(self._angles_at(np.array([t_end]))[0].tolist())
        self._out.append(ImuGap(t_start, t_end, self._last_angles, end_angles))
        self._history = []
        self._last_angles = end_angles
        self._next = resume

    def _angles_at(self, t: np.ndarray) -> np.ndarray:
        return self._table.at(t, MAX_ANGLE_GAP_S) if self.with_table else np.full((len(t), 3), np.nan)

    def _fill(self, start: int, resume: int) -> tuple[np.ndarray, np.ndarray]:
        """Increments (n, 3) of the missing samples from the cubic through the cumulative sums around the gap."""
        (k1, th1, v1, _), (k2, th2, v2, _) = self._history
        known = (float(k1 - 1), float(k1), float(k2))
        th = cumulative_cubic(known, (np.zeros(3), th1, th1 + th2), float(resume), (self._dtheta[0], self._dtheta[1]))
        v = cumulative_cubic(known, (np.zeros(3), v1, v1 + v2), float(resume), (self._dv[0], self._dv[1]))
        k = range(start, resume)
        return np.array([th(j) - th(j - 1) for j in k]), np.array([v(j) - v(j - 1) for j in k])


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
