"""Sync pairing: the IMU's counter and the table's pulse count put on one pulse line, found from the data.

Each device counts from its own start (the IMU's counter wraps; the decoder unwraps it), and the harness
opens the ports whenever it starts, so a sample's pulse is its stream's counter plus an offset that this
stage finds, watches and re-finds (docs/harness.md, "Sync pairing"):

- **Receive times** (coarse): the newest frame of a read left its device a frame's wire time before it
  arrived, plus a latency that is small for the freshest reads. Per read, ``e = R (h - h_ref) - R wire -
  counter`` (pulses; R the pulse rate on the host's clock) is the stream's lateness less its offset; its
  minimum over many reads, against the other stream's, gives the offset to within the reads' jitter.
- **Motion** (exact): within that jitter, the offset that makes the gyro increments sum to the rotation the
  table angles show (:mod:`hil.pipeline.motion_match`). A table that shows no motion is paired by receive
  time alone, and the report says so with the accuracy that gives.
- **Watch**: a paired stream's reads are held against its baseline (the minimum lateness of its last
  ``WINDOW_S``): a frame earlier than its pulse allows breaks the pairing at once; reads later than the
  jitter allows are held, and ``SUSPECT_READS`` of them in a row break it (a power cycle, a replug, wraps
  lost in a stall), while one on time releases them (the host was only late). A reconnected port is
  re-paired. While paired by motion, every ``CHECK_S`` the gyros are matched against the table again.
  A broken stream's samples wait (at most ``HOLD_S``) for the new offset; what cannot wait is counted
  ``unpaired``, never estimated against angles of an unconfirmed pairing.

The table is the reference: its first offset is 0, so the pulse line is the table's count; a table that
breaks is re-paired on its own receive times, the IMU by motion against it. At ``--speed max`` the host
times say nothing of the devices' (the emulator then starts its pulse train once both ports have a reader,
and its first frames arrive together), and the coarse offset is the difference of the streams' first counters,
searched by motion over ``UNPACED_SEARCH_S``. Every decision depends only on
the samples and their recorded receive times, so a replay pairs exactly as the live run did.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hil.pipeline.motion_match import MIN_INTERVALS, Match, TableRotations, best_offset
from hil.pipeline.pairing_streams import MIN_READS, Samples, StreamPairing, joined, kept, part, shifted
from hil.samples import ImuSamples, TableSamples

WINDOW_S = 10.0  # host seconds of reads behind a stream's receive-time baseline
SUSPECT_READS = 4  # late reads in a row that break a pairing
HOLD_S = 5.0  # samples wait this long (of their own time) for a pairing; older ones are dropped as unpaired
HISTORY_S = 4.0  # paired samples kept for the motion checks
CHECK_S = 2.0  # a paired IMU is checked against the table's motion this often (of IMU time)
STILL_S = 1.0  # table data before a table at rest is paired by receive time
MIN_TOLERANCE_S = 0.003  # host seconds: the least lateness the watch allows for
JITTER_FACTOR = 3.0  # the watch allows this many times the reads' spread (90th percentile over minimum)
SEARCH_S = 0.02  # at least this much of either side of the coarse offset is searched by motion
UNPACED_SEARCH_S = 1.0
RETRY_S = 0.2  # of new table data before a waiting IMU is searched by motion again
MOTION, RECEIVE_TIME = "motion", "receive_time"


@dataclass
class SyncReport:
    """result.json ``streams.sync``."""

    paired_by: str | None = None
    offset_pulses: int | None = None  # the IMU's pulse minus its unwrapped counter, in the table's count
    confirmed_at_s: float | None = None  # trial time of the newest sample when the motion confirmed the pairing
    accuracy_ms: float | None = None  # receive-time pairing: the reads' jitter it is good to
    repairs: list[dict] = field(default_factory=list)  # {"at_s", "cause"}
    unpaired: int = 0  # IMU samples dropped without a pairing

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class SyncPairing:
    """Pairs the two streams' counters on one pulse line; :meth:`add_imu` / :meth:`add_table` take one read's
    samples (counters unwrapped by the decoder) and return what is now paired, with ``sync_index`` the pulse.

    ``rate_hz`` is the pulse train's rate, ``table_step`` the counts between table frames, ``imu_modulus`` the
    IMU counter's (None: no counter), ``time_scale`` the devices' speed on the host's clock (None: unpaced),
    ``wire_s`` the (IMU, table) frames' time on their lines, ``rotations`` builds the table's interval
    rotations from (counts, angles).
    """

    def __init__(self, rate_hz: float, table_step: int, imu_modulus: int | None, time_scale: float | None,
                 wire_s: tuple[float, float], rotations: Callable[[np.ndarray, np.ndarray], TableRotations]) -> None:
        self.rate = rate_hz
        self.host_rate = None if time_scale is None else rate_hz * time_scale  # pulses per host second
        self.table_step = table_step
        self.imu_modulus = imu_modulus
        self.rotations = rotations
        self.imu = StreamPairing("imu", wire_s[0] * rate_hz)
        self.table = StreamPairing("table", wire_s[1] * rate_hz, offset=0)  # the table's count is the pulse line
        self.report = SyncReport()
        self.failure: str | None = None  # why the streams cannot be paired (ends a live trial)
        self._h_ref: float | None = None
        self._imu_history = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))  # paired (pulse, dtheta)
        self._table_history = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))  # paired (pulse, angles)
        self._checked = 0  # IMU pulse of the last motion check
        self._table_first: int | None = None  # the first table pulse
        self._first_pulse: int | None = None  # the first IMU pulse paired: trial times count from it

    # -- the reads ---------------------------------------------------------------------------------

    def add_imu(self, samples: ImuSamples) -> tuple[TableSamples | None, ImuSamples | None]:
        """One IMU read; returns the (table, IMU) samples now paired."""
        released = self._read(self.imu, samples)
        if released is not None and self.report.paired_by is not None:
            self._remember_imu(released)
            self._check_motion(released)
        return None, released

    def add_table(self, samples: TableSamples) -> tuple[TableSamples | None, ImuSamples | None]:
        """One table read; returns the (table, IMU) samples now paired (a table read may settle the IMU's)."""
        released = self._read(self.table, samples)
        if released is not None:
            self._remember_table(released)
        imu = self._settle(self.imu) if self.imu.offset is None and self.imu.held else None
        if imu is not None:
            self._remember_imu(imu)
        return released, imu

    def event(self, stream: str, kind: str) -> None:
        """A reader's event: a reconnected port is paired anew (the device may have restarted)."""
        s = self.imu if stream == "imu" else self.table
        if kind == "reconnected" and s.offset is not None:
            self._break(s, "reconnected after an outage")

    def flush(self) -> tuple[TableSamples | None, ImuSamples | None]:
        """End of data: the (table, IMU) samples of late reads of paired streams, which no later read can judge
        now, are paired as they were; IMU samples still waiting for a pairing are unpaired."""
        out = []
        for s in (self.table, self.imu):
            if s.offset is not None and s.held:
                released, s.held = shifted(joined(s.held), s.offset), []
                out.append(released)
            else:
                out.append(None)
        self._drop(self.imu, len(self.imu.held))
        return out[0], out[1]

    # -- one read ----------------------------------------------------------------------------------

    def _read(self, s: StreamPairing, samples: Samples) -> Samples | None:
        """One read of ``s``: what of it (and of earlier reads) is now paired, on the pulse line."""
        released = self._judged(s, samples)
        early, s.before_break = s.before_break, None
        parts = [part for part in (early, released) if part is not None and len(part)]
        return joined(parts) if parts else None

    def _judged(self, s: StreamPairing, samples: Samples) -> Samples | None:
        if not len(samples):
            return None
        h = float(samples.host_time[-1])
        if self._h_ref is None:
            self._h_ref = h
        e = self._lateness(s, h, int(samples.sync_index[-1]))
        if s.offset is None:
            s.held.append(samples)
            s.segment.append((h, e))
            self._trim_held(s)
            return self._settle(s)
        late = e - s.offset
        baseline = s.baseline() if self.host_rate is not None else None
        if baseline is not None and abs(late - baseline) > self.tolerance():
            s.held.append(samples)
            s.segment.append((h, e))
            s.late += 1
            if s.late < SUSPECT_READS:
                return None
            self._break(s, f"frames arrived {'later' if late > baseline else 'earlier'} than their pulses allow for "
                           f"{SUSPECT_READS} reads (counter reset, replug or wraps lost)")
            return self._settle(s)
        released = joined([*s.held, samples])
        s.held, s.segment, s.late = [], [], 0
        s.window.append((h, late))
        while s.window and s.window[0][0] < h - WINDOW_S:
            s.window.popleft()
        return shifted(released, s.offset)

    def _lateness(self, s: StreamPairing, h: float, counter: int) -> float:
        """Pulses from the newest frame's pulse (less the stream's offset) to its arrival: ``e``."""
        if self.host_rate is None:
            return 0.0
        return self.host_rate * (h - self._h_ref) - s.wire - counter

    def jitter(self, quantile: float = 0.9) -> float:
        """Pulses the reads' lateness scatters by (its ``quantile`` over its least, the worse stream's)."""
        return max(self.imu.spread(quantile), self.table.spread(quantile))

    def tolerance(self) -> float:
        """Pulses of lateness the watch allows: ``JITTER_FACTOR`` times the jitter, at least ``MIN_TOLERANCE_S``."""
        return max(2.0, MIN_TOLERANCE_S * self.host_rate, JITTER_FACTOR * self.jitter())

    def _break(self, s: StreamPairing, cause: str) -> None:
        """The stream's pairing broke where its counter last jumped within the held reads (else before them):
        the samples before that are paired as they were (:attr:`StreamPairing.before_break`), the rest start the new
        segment with the reads that brought them."""
        step = 1 if s is self.imu else self.table_step
        held = joined(s.held) if s.held else None
        jumps = np.flatnonzero(np.diff(held.sync_index) != step) if held is not None else []
        late = np.array([e for _, e in s.segment])
        steps = np.abs(np.diff(late))  # a counter that went on by the frames it sent, but not by the time that passed
        ends = np.cumsum([len(part) for part in s.held])  # a read's samples end there in ``held``
        cut = int(jumps[-1]) + 1 if len(jumps) else 0
        if not cut and len(steps) and steps.max() > self.tolerance():
            cut = int(ends[int(np.argmax(steps))])
        if cut:
            s.before_break = shifted(part(held, np.arange(cut)), s.offset)
            s.segment = [read for read, end in zip(s.segment, ends, strict=True) if end > cut]
            s.held = [part(held, np.arange(cut, len(held)))]
        s.cause = cause
        s.offset_before = s.offset
        s.offset = None
        s.late = 0
        if s is self.imu:  # the motion checks compare the streams from here on
            self._imu_history = (self._imu_history[0][:0], self._imu_history[1][:0])
        else:
            self._table_history = (self._table_history[0][:0], self._table_history[1][:0])
            self._checked = 0  # the IMU is checked against the table's new segment as soon as it can be

    # -- settling a pairing ------------------------------------------------------------------------

    def _settle(self, s: StreamPairing) -> Samples | None:
        """Pair a waiting stream once its data allow; returns its held samples, paired, or None."""
        coarse = self._coarse(s)
        if coarse is None:
            return None
        if s is self.table:
            return self._paired(s, self._receive_time_offset(s, coarse), RECEIVE_TIME)
        pulses, _ = self._table_history
        if not len(pulses) or (s.tried is not None and pulses[-1] - s.tried < RETRY_S * self.rate):
            return None
        s.tried = int(pulses[-1])
        search = math.ceil(max(2 * self.tolerance(), SEARCH_S * self.host_rate, self._backlog(s))
                           if self.host_rate is not None else UNPACED_SEARCH_S * self.rate)
        match = self._match(joined(s.held), np.arange(coarse - search, coarse + search + 1))
        if match.offset is not None:
            return self._paired(s, match.offset, MOTION)
        table_span = (pulses[-1] - pulses[0]) / self.rate
        if (not match.moving and table_span >= STILL_S) or s.waited(self.rate) >= HOLD_S:
            return self._paired(s, self._receive_time_offset(s, coarse), RECEIVE_TIME)
        return None

    def _backlog(self, s: StreamPairing) -> float:
        """Pulses by which the segment's reads were late at worst against their least: after a stall of the
        host its first reads bring old frames, and the least lateness may not yet be a prompt read's."""
        late = [e for _, e in s.segment]
        return max(late) - min(late) + self.tolerance()

    def _receive_time_offset(self, s: StreamPairing, coarse: int) -> int:
        """The offset by receive time alone: the one before the break where the receive times cannot tell them
        apart (a host that was late broke it, not the device)."""
        if s.offset_before is not None and self.host_rate is not None and abs(coarse - s.offset_before) <= \
                self.tolerance():
            return s.offset_before
        return coarse

    def _coarse(self, s: StreamPairing) -> int | None:
        """The offset the receive times give (None until they can)."""
        if self.host_rate is None:
            if s.offset_before is not None:
                return s.offset_before  # reconnected: the unwrapped count carries on, unless the device restarted
            first = self._table_first
            return None if first is None else first - int(s.held[0].sync_index[0])
        if len(s.segment) < MIN_READS and s.waited(self.rate) < STILL_S:
            return None
        other = self.table if s is self.imu else self.imu
        baseline = s.baseline(1)
        if baseline is None:
            baseline = other.baseline(1) if other.offset is not None else None
        if baseline is None:
            return None
        jitter = self.jitter(0.5)  # the least lateness is found while half the reads are prompt
        if s is self.imu and self.imu_modulus and jitter >= self.imu_modulus / 2:
            jitter_ms, half_ms = (1e3 * x / self.host_rate for x in (jitter, self.imu_modulus / 2))
            self.failure = (f"the receive times scatter by {jitter_ms:.0f} ms, more than half the IMU counter's "
                            f"period ({half_ms:.0f} ms): its counter cannot be paired with the table's; read the "
                            f"ports faster (a lower-latency host or adapter), lower imu.rate_hz, or use a device "
                            f"with a wider counter")
            return None
        return round(min(e for _, e in s.segment) - baseline)

    def _match(self, imu: ImuSamples, candidates: np.ndarray) -> Match:
        pulses, angles = self._table_history
        return best_offset(imu.sync_index, imu.dtheta, self.rotations(pulses, angles), candidates)

    def _paired(self, s: StreamPairing, offset: int, by: str) -> Samples | None:
        """Settle ``s`` at ``offset``: its held samples go out on the pulse line."""
        first = self.report.paired_by is None and s is self.imu
        changed = s.cause is not None and offset != s.offset_before
        s.offset = offset
        if not s.window and self.host_rate is not None:  # the first pairing; a re-pairing keeps the baseline
            s.window = deque((h, e - offset) for h, e in s.segment)
        released = shifted(joined(s.held), offset)
        s.held, s.segment, s.tried = [], [], None
        if first:
            keep = released.sync_index > self._table_first - self.table_step  # no angles more than a table frame before
            self._drop_count(int(np.count_nonzero(~keep)))
            if keep.any():
                self._first_pulse = int(released.sync_index[keep][0])
        at = self._trial_time(int(released.sync_index[-1]))
        released = released.take(keep) if first else released
        if s is self.imu:
            self.report.offset_pulses = offset - (self.table.offset or 0)
            self._set_by(by, at)
        if changed:
            self.report.repairs.append({"at_s": round(at, 6), "cause": f"{s.name}: {s.cause}"})
        s.cause = None
        self._checked = int(released.sync_index[-1]) if s is self.imu and len(released) else self._checked
        return released if len(released) else None

    def _set_by(self, by: str, at: float) -> None:
        self.report.paired_by = by
        self.report.confirmed_at_s = round(at, 6) if by == MOTION else None
        self.report.accuracy_ms = None if by == MOTION or self.host_rate is None else round(
            1e3 * self.tolerance() / self.host_rate, 3)

    # -- watching a paired IMU by motion -----------------------------------------------------------

    def _check_motion(self, released: ImuSamples) -> None:
        """Every ``CHECK_S``, the gyros against the table: a better offset nearby re-pairs the IMU; a pairing
        by receive time that the motion confirms becomes one by motion."""
        newest = int(released.sync_index[-1])
        if newest - self._checked < CHECK_S * self.rate or not len(self._table_history[0]):
            return
        search = math.ceil(self.tolerance()) + 2 if self.host_rate is not None else 3
        pulses, dtheta = self._imu_history
        match = self._match(ImuSamples(pulses, dtheta, dtheta, np.zeros(len(pulses)), np.zeros(len(pulses))),
                            np.arange(-search, search + 1))
        if match.moving and match.intervals < MIN_INTERVALS:
            return  # too little data since a break: again at the next read
        self._checked = newest
        if match.offset is None:
            return
        at = self._trial_time(newest)
        if match.offset:
            self.imu.offset += match.offset
            self.report.offset_pulses = self.imu.offset - (self.table.offset or 0)
            self.report.repairs.append({"at_s": round(at, 6), "cause": f"imu: gyro/table disagreement "
                                                                       f"({match.offset:+d} pulses)"})
            self._imu_history = (pulses + match.offset, dtheta)
            self.imu.window = deque((h, v - match.offset) for h, v in self.imu.window)
        if self.report.paired_by != MOTION or match.offset:
            self._set_by(MOTION, at)

    # -- bookkeeping -------------------------------------------------------------------------------

    def _trial_time(self, pulse: int) -> float:
        """Seconds of the pulse train from the first IMU sample paired (or this one) to ``pulse``."""
        if self._first_pulse is None:
            self._first_pulse = pulse
        return (pulse - self._first_pulse) / self.rate

    def _remember_imu(self, samples: ImuSamples) -> None:
        self._imu_history = kept(self._imu_history, samples.sync_index, samples.dtheta, HISTORY_S * self.rate)

    def _remember_table(self, samples: TableSamples) -> None:
        if self._table_first is None:
            self._table_first = int(samples.sync_index[0])
        self._table_history = kept(self._table_history, samples.sync_index, samples.angles, HISTORY_S * self.rate)

    def _trim_held(self, s: StreamPairing) -> None:
        """At most ``HOLD_S`` of a waiting stream's samples are held; older IMU samples are unpaired."""
        newest = int(s.held[-1].sync_index[-1])
        while len(s.held) > 1 and newest - int(s.held[0].sync_index[-1]) > HOLD_S * self.rate:
            dropped = s.held.pop(0)
            if s is self.imu:
                self._drop_count(len(dropped))

    def _drop(self, s: StreamPairing, reads: int) -> None:
        for dropped in s.held[:reads]:
            self._drop_count(len(dropped))
        s.held = s.held[reads:]

    def _drop_count(self, n: int) -> None:
        self.report.unpaired += n
