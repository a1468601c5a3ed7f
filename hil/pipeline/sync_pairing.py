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
- **Receive times alone** (``by_motion`` False, a frequency response's live form): the IMU is paired once
  ``RECEIVE_S`` of its reads are held, at the offset their least lateness gives, and never moved by its motion:
  a gyro that lags the table (its low-pass, its output delay) would pull the motion's offset by that lag
  rounded to whole pulses, and a frequency response measures that lag. Good while the least lateness of
  ``RECEIVE_S`` of each stream's reads is within half a pulse of the other's (docs/ratetests.md).

The table is the reference: its first offset is 0, so the pulse line is the table's count. A table that
breaks is re-paired by its motion against the paired IMU's, searched around the offset its receive times give
(alone they can put it a pulse off, and every IMU sample would meet the angles of the pulse next to its own);
its samples wait for that as a broken IMU's do, and where the motion cannot tell (or the IMU is not paired, or
by its receive times alone) its receive times place it. At ``--speed max`` the host times say nothing of the
devices' (the emulator then starts its pulse train once both ports have a reader, and its first frames arrive
together), and the coarse offset is the difference of the streams' first counters, searched by motion over
``UNPACED_SEARCH_S``. Every decision depends only on the samples and their recorded receive times, so a replay
pairs exactly as the live run did.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hil.pipeline.motion_match import MIN_INTERVALS, PairedMotion, TableRotations
from hil.pipeline.pairing_streams import Samples, StreamPairing, joined, part, shifted
from hil.pipeline.receive_times import STILL_S, ReceiveTimes
from hil.samples import ImuSamples, TableSamples
from hil.vocabulary import PairedBy, Stream, StreamEventKind

WINDOW_S = 10.0  # host seconds of reads behind a stream's receive-time baseline
SUSPECT_READS = 4  # late reads in a row that break a pairing
HOLD_S = 5.0  # samples wait this long (of their own time) for a pairing; older ones are dropped as unpaired
HISTORY_S = 4.0  # paired samples kept for the motion checks
CHECK_S = 2.0  # a paired IMU is checked against the table's motion this often (of IMU time)
SEARCH_S = 0.02  # at least this much of either side of the coarse offset is searched by motion
UNPACED_SEARCH_S = HOLD_S  # a reader's flush on opening may take up to this much of a stream's first frames
RETRY_S = 0.2  # of new table data before a waiting IMU is searched by motion again
RECEIVE_S = 4.0  # of the IMU's reads held before their receive times alone pair it (one second's can be a pulse off)
MOTION, RECEIVE_TIME = PairedBy.MOTION, PairedBy.RECEIVE_TIME


@dataclass
class SyncReport:
    """result.json ``streams.sync``."""

    paired_by: PairedBy | None = None
    offset_pulses: int | None = None  # the IMU's pulse minus its unwrapped counter, in the table's count
    confirmed_at_s: float | None = None  # trial time of the newest sample when the motion confirmed the pairing
    accuracy_ms: float | None = None  # receive-time pairing: the reads' jitter it is good to
    repairs: list[dict] = field(default_factory=list)  # {"at_s", "cause"}
    unpaired: int = 0  # IMU samples dropped without a pairing

    def as_dict(self) -> dict:
        return dict(self.__dict__)

    def paired(self, by: PairedBy, at: float, accuracy_ms: float | None) -> None:
        """Paired ``by`` motion or receive time, at trial time ``at`` (s), good to ``accuracy_ms`` (receive time)."""
        self.paired_by = by
        self.confirmed_at_s = round(at, 6) if by == MOTION else None
        self.accuracy_ms = None if accuracy_ms is None else round(accuracy_ms, 3)


class SyncPairing:
    """Pairs the two streams' counters on one pulse line; :meth:`add_imu` / :meth:`add_table` take one read's
    samples (counters unwrapped by the decoder) and return what is now paired, with ``sync_index`` the pulse.

    ``rate_hz`` is the pulse train's rate, ``table_step`` the counts between table frames, ``imu_modulus`` the
    IMU counter's (None: no counter), ``time_scale`` the devices' speed on the host's clock (None: unpaced),
    ``wire_s`` the (IMU, table) frames' time on their lines, ``rotations`` builds the table's interval
    rotations from (counts, angles); ``by_motion`` False: the IMU is paired by its receive times alone (paced).
    """

    def __init__(self, rate_hz: float, table_step: int, imu_modulus: int | None, time_scale: float | None,
                 wire_s: tuple[float, float], rotations: Callable[[np.ndarray, np.ndarray], TableRotations],
                 by_motion: bool = True) -> None:
        self.rate = rate_hz
        self.host_rate = None if time_scale is None else rate_hz * time_scale  # pulses per host second
        self.table_step = table_step
        self.imu = StreamPairing(Stream.IMU, wire_s[0] * rate_hz)
        self.table = StreamPairing(Stream.TABLE, wire_s[1] * rate_hz, offset=0)  # the table's count is the pulse line
        self.receive = ReceiveTimes(self.host_rate, self.imu, self.table, imu_modulus)
        self.motion = PairedMotion(rate_hz, HISTORY_S, rotations)
        self.report = SyncReport()
        self._checked = 0  # IMU pulse of the last motion check
        self._first_pulse: int | None = None  # the first IMU pulse paired: trial times count from it
        self._unconfirmed = 0  # pulses either side of a receive-time pairing that its motion checks search
        self.by_motion = by_motion or time_scale is None  # unpaced, the receive times say nothing

    @property
    def failure(self) -> str | None:
        """Why the streams cannot be paired (ends a live trial)."""
        return self.receive.failure

    def add_imu(self, samples: ImuSamples) -> tuple[TableSamples | None, ImuSamples | None]:
        """One IMU read; returns the (table, IMU) samples now paired."""
        released = self._read(self.imu, samples)
        if released is not None and self.report.paired_by is not None and self.by_motion:
            self.motion.add_imu(released.sync_index, released.dtheta)
            self._check_motion(released)
        return None, released

    def add_table(self, samples: TableSamples) -> tuple[TableSamples | None, ImuSamples | None]:
        """One table read; returns the (table, IMU) samples now paired (a table read may settle the IMU's)."""
        released = self._read(self.table, samples)
        if released is not None:
            self.motion.add_table(released.sync_index, released.angles)
        imu = self._settle(self.imu) if self.imu.offset is None and self.imu.held else None
        if imu is not None:
            self.motion.add_imu(imu.sync_index, imu.dtheta)
        return released, imu

    def event(self, stream: str, kind: str) -> None:
        """A reader's event: a reconnected port is paired anew (the device may have restarted)."""
        s = self.imu if stream == Stream.IMU else self.table
        if kind == StreamEventKind.RECONNECTED and s.offset is not None:
            self._break(s, "reconnected after an outage")

    def flush(self) -> tuple[TableSamples | None, ImuSamples | None]:
        """End of data: the (table, IMU) samples of late reads of paired streams, which no later read can judge
        now, are paired as they were; IMU samples still waiting for a pairing are unpaired."""
        table, imu = self.table.flushed(), self.imu.flushed()
        self.report.unpaired += sum(len(read) for read in self.imu.held)
        self.imu.held = []
        return table, imu

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
        s.first = int(samples.sync_index[0]) if s.first is None else s.first
        e = self.receive.lateness(s, h, int(samples.sync_index[-1]))
        if s.offset is None:
            s.held.append(samples)
            s.segment.append((h, e))
            dropped = s.trim(HOLD_S * self.rate)  # at most HOLD_S of a waiting stream's samples are held
            self.report.unpaired += dropped if s is self.imu else 0  # older IMU samples are unpaired
            return self._settle(s)
        late = e - s.offset
        baseline = s.baseline() if self.host_rate is not None else None
        if baseline is not None and abs(late - baseline) > self.receive.tolerance():
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

    def _break(self, s: StreamPairing, cause: str) -> None:
        """The stream's pairing broke (:meth:`StreamPairing.broken`); the motion checks compare the streams
        from its new segment on."""
        s.broken(1 if s is self.imu else self.table_step, self.receive.tolerance, cause)
        if s is self.imu:
            self.motion.forget_imu()
        else:
            self.motion.forget_table()
            self._checked = 0  # the IMU is checked against the table's new segment as soon as it can be

    def _settle(self, s: StreamPairing) -> Samples | None:
        """Pair a waiting stream (by motion: the IMU against the table, a broken table against the IMU) once its
        data allow; returns its held samples, paired, or None."""
        receive = self.receive
        coarse = receive.coarse(s, self.rate, self.motion.table_first)
        if coarse is None:
            return None
        imu_history = self.imu.offset is not None and len(self.motion.imu[0])  # what a broken table is matched to
        if not self.by_motion or (s is self.table and not imu_history):  # by receive time (the IMU's: RECEIVE_S held)
            held_enough = s is self.table or s.waited(self.rate) >= RECEIVE_S
            return self._paired(s, receive.offset(s, coarse), RECEIVE_TIME) if held_enough else None
        held = joined(s.held)
        pulses = self.motion.table[0] if s is self.imu else held.sync_index  # the table's data searched
        if not len(pulses) or (s.tried is not None and pulses[-1] - s.tried < RETRY_S * self.rate):
            return None
        s.tried = int(pulses[-1])
        search = math.ceil(max(2 * receive.tolerance(), SEARCH_S * self.host_rate, receive.backlog(s))
                           if self.host_rate is not None else UNPACED_SEARCH_S * self.rate)
        match = self.motion.match_held(held, np.arange(coarse - search, coarse + search + 1))
        if match.offset is not None:
            return self._paired(s, match.offset, MOTION)
        table_span = (pulses[-1] - pulses[0]) / self.rate
        if (not match.moving and table_span >= STILL_S) or s.waited(self.rate) >= HOLD_S:
            self._unconfirmed = search  # the motion checks search this much until the motion decides
            return self._paired(s, receive.offset(s, coarse), RECEIVE_TIME)
        return None

    def _paired(self, s: StreamPairing, offset: int, by: PairedBy) -> Samples | None:
        """Settle ``s`` at ``offset``: its held samples go out on the pulse line."""
        first = self.report.paired_by is None and s is self.imu
        changed = s.cause is not None and offset != s.offset_before
        s.offset = offset
        if not s.window and self.host_rate is not None:  # the first pairing; a re-pairing keeps the baseline
            s.window = deque((h, e - offset) for h, e in s.segment)
        released = shifted(joined(s.held), offset)
        s.held, s.segment, s.tried = [], [], None
        if first:
            # no angles more than a table frame before the table's first
            keep = released.sync_index > self.motion.table_first - self.table_step
            self.report.unpaired += int(np.count_nonzero(~keep))
            if keep.any():
                self._first_pulse = int(released.sync_index[keep][0])
        at = self._trial_time(int(released.sync_index[-1]))
        released = released.take(keep) if first else released
        if self.imu.offset is not None:  # the streams are paired again: the IMU now, or the table to it
            self.report.offset_pulses = self.imu.offset - (self.table.offset or 0)
            self._set_by(by, at)
        if changed:
            self.report.repairs.append({"at_s": round(at, 6), "cause": f"{s.name}: {s.cause}"})
        s.cause = None
        self._checked = int(released.sync_index[-1]) if s is self.imu and len(released) else self._checked
        return released if len(released) else None

    def _set_by(self, by: PairedBy, at: float) -> None:
        accuracy = None if by == MOTION or self.host_rate is None else 1e3 * self.receive.tolerance() / self.host_rate
        self.report.paired(by, at, accuracy)

    # -- watching a paired IMU by motion -----------------------------------------------------------

    def _check_motion(self, released: ImuSamples) -> None:
        """Every ``CHECK_S``, the gyros against the table: a better offset nearby re-pairs the IMU; a pairing
        by receive time, searched over the whole of its coarse offset's uncertainty, becomes one by motion
        once the motion decides (at the offset it had or at a better one)."""
        newest = int(released.sync_index[-1])
        if newest - self._checked < CHECK_S * self.rate or not len(self.motion.table[0]):
            return
        near = math.ceil(self.receive.tolerance()) + 2 if self.host_rate is not None else 3
        search = near if self.report.paired_by == MOTION else self._unconfirmed
        match = self.motion.match(*self.motion.imu, np.arange(-search, search + 1))
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
            self.motion.forget_imu(shift=match.offset)
            self.imu.window = deque((h, v - match.offset) for h, v in self.imu.window)
        if self.report.paired_by != MOTION or match.offset:
            self._set_by(MOTION, at)

    def _trial_time(self, pulse: int) -> float:
        """Seconds of the pulse train from the first IMU sample paired (or this one) to ``pulse``."""
        if self._first_pulse is None:
            self._first_pulse = pulse
        return (pulse - self._first_pulse) / self.rate
