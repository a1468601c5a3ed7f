"""Stream framing for byte protocols: find sync words, check frames, resynchronise, count.

Every byte fed ends up in exactly one of: a decoded frame, ``counters.skipped_bytes``, or the
buffer awaiting more data (:attr:`ByteFramer.buffered`). After a bad frame the search restarts one
byte after its sync word, so an intact frame that follows damage is always found.

A read is framed as a whole: every sync word in it is located at once, the frames behind them are
checked and unpacked as arrays by the codec, and only where frames overlap (damage, a false sync)
are the candidates walked one by one; the counters are unwrapped for all frames of the read at once.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from typing import ClassVar, NamedTuple

import numpy as np

from drivers.codec import Codec, Counters, DecodeError, FrameBatch, Framer, R, RawChunk


def host_rate(rate_hz: float | None, time_scale: float | None) -> float | None:
    """Frames per host second of a device at ``rate_hz`` running ``time_scale`` times faster than real
    time (an emulator at ``--speed X``); None when the host times say nothing of the device's (``--speed
    max``, or no known rate), so that only the counters are used."""
    return None if not rate_hz or time_scale is None else rate_hz * time_scale


class SequenceUnwrapper:
    """Unwraps a device counter that counts modulo ``modulus`` into a monotonic index.

    A counter that did not move is a repeated frame, and one that stepped back by at most
    ``REORDER_WINDOW`` frames is a late (out-of-order) frame: neither moves the index, and :meth:`next_many`
    marks them with a missing count of -1. Devices never repeat a number, so when the host receive
    times say that about a counter period or more has passed, the same readings are taken as wraps.
    With the device rate known, the host receive times also resolve wraps lost in an outage longer
    than the counter period (a 7-bit counter at 1 kHz wraps every 128 ms). They do so only where bytes
    were lost: a frame whose bytes directly follow the previous frame's (``adjacent``) lost nothing in
    between, however late it came (a writer or a host that was held up).

    A wide counter (16 bits and more) that jumps ahead by more than ``JUMP_LIMIT`` frames, where the
    host times do not explain the jump, is taken as damage a weak checksum let through: the frame is
    counted corrupt (missing -2) and the index stays, unless the next frame continues from it (a
    counter reset), which then moves the index.

    A device may count ``counts_per_frame`` between frames (a table latching every n-th pulse of a
    train it counts): the index stays in counts while the missing count is in frames. The first counter
    may have any value.
    """

    REORDER_WINDOW = 8  # frames; a backward step larger than this is taken as a wrap
    JUMP_LIMIT = 1024  # frames; a wide counter jumping further needs the next frame to confirm it

    def __init__(self, modulus: int | None, rate_hz: float | None = None, counts_per_frame: int = 1) -> None:
        if counts_per_frame < 1:
            raise ValueError(f"counts_per_frame must be at least 1, got {counts_per_frame}")
        self.modulus = modulus
        self.rate_hz = rate_hz  # frames per second
        self.counts_per_frame = counts_per_frame
        self._index: int | None = None
        self._sequence = 0
        self._time = math.nan
        self._suspect: int | None = None  # counter of an unconfirmed far jump

    def next_many(self, sequences: np.ndarray | None, host_times: np.ndarray, adjacent: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(index of each frame, frames missing since the one before it, repeated) of consecutive frames
        (``sequences`` int64, -1 or None where a frame has no counter). Missing is -1 for a repeated or late
        frame, whose index is then the earlier one it carries (``repeated`` True where it is a repeat rather
        than a late frame), and -2 for an implausible jump.

        ``adjacent`` marks frames whose bytes directly follow the previous frame's: no byte was lost
        between them, so their host times size nothing (a writer that was held up, not an outage).

        The frames are taken in runs: each run is computed at once as if every frame continued from
        the one before it, up to the first frame that does not (a repeat, a late frame, a far jump),
        which is settled before the next run starts from it."""
        n = len(host_times)
        index, missing = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        repeated = np.zeros(n, dtype=bool)
        has = np.ones(n, dtype=bool) if sequences is None else sequences >= 0
        if sequences is None or self.modulus is None:
            has[:] = False
        seq = np.where(has, sequences if sequences is not None else 0, 0).astype(np.int64)
        untimed = np.zeros(n, dtype=bool) if adjacent is None else adjacent
        i = 0
        if n and self._index is None:
            self._index = int(seq[0]) if has[0] else 0
            self._sequence, self._time = int(seq[0]), float(host_times[0])
            index[0] = self._index
            i = 1
        while i < n:
            i = self._run(seq[i:], has[i:], host_times[i:], untimed[i:], index[i:], missing[i:], repeated[i:]) + i
        return index, missing, repeated

    def _run(self, seq: np.ndarray, has: np.ndarray, times: np.ndarray, untimed: np.ndarray, index: np.ndarray,
             missing: np.ndarray, repeated: np.ndarray) -> int:
        """Settle the frames up to and including the first that does not continue from the one before it;
        returns how many were settled (filling ``index``, ``missing``, ``repeated`` from the start)."""
        n, modulus = self.counts_per_frame, self.modulus or 1
        previous = np.concatenate(([self._sequence], seq[:-1]))
        previous_time = np.concatenate(([self._time], times[:-1]))
        step = np.where(has, (seq - previous) % modulus, n)
        host_counts = (times - previous_time) * (self.rate_hz or math.nan) * n  # counts by the host clock
        host_counts[untimed] = math.nan
        if (self._suspect is None and (step == n).all() and modulus - n > min(self.REORDER_WINDOW * n, modulus // 4)
                and not ((host_counts - n) / modulus > 0.5).any()):
            # every frame the next one (no repeat, no late frame, no wrap the host times tell of)
            index[:] = self._index + n * np.arange(1, len(seq) + 1)
            self._index, self._sequence, self._time = int(index[-1]), int(seq[-1]), float(times[-1])
            return len(seq)
        timed = np.isfinite(host_counts)
        back = (modulus - step) % modulus
        late = has & (back <= min(self.REORDER_WINDOW * n, modulus // 4)) & ~(timed & (host_counts > modulus / 2))
        step = np.where(step == 0, modulus, step)
        timed &= has
        wraps = np.where(timed, np.round((np.where(timed, host_counts, 0.0) - step) / modulus), 0.0)
        step = step + modulus * np.maximum(wraps, 0.0).astype(np.int64)
        limit = self.JUMP_LIMIT * n
        far = has & (step > limit) & (modulus > 4 * limit) & ~(timed & (np.abs(host_counts - step) < limit))
        if self._suspect is not None and has[0] and seq[0] == (self._suspect + n) % modulus:
            far[0] = False  # the far jump before was a counter reset: this frame confirms it, and the index goes
            step[0] = n * max(1, round(host_counts[0] / n)) if timed[0] else n  # on by the time that passed
        odd = np.flatnonzero(late | far)
        stop = int(odd[0]) if len(odd) else len(seq)
        if stop:
            index[:stop] = self._index + np.cumsum(step[:stop])
            missing[:stop] = np.maximum(np.round(step[:stop] / n).astype(np.int64) - 1, 0)
            self._suspect = None
            self._index = int(index[stop - 1])
            self._sequence = int(seq[stop - 1])
            self._time = float(times[stop - 1])
        if stop == len(seq):
            return stop
        if late[stop]:
            index[stop], missing[stop], repeated[stop] = self._index - back[stop], -1, back[stop] == 0
        else:  # a frame whose damage the checksum missed, or a counter reset
            self._suspect = int(seq[stop])
            index[stop], missing[stop] = self._index, -2
        return stop + 1

    def count_many(self, counters: Counters, missing: np.ndarray, repeated: np.ndarray) -> np.ndarray:
        """Add :meth:`next_many` outcomes to ``counters``; the frames to deliver (mask)."""
        if not missing.any():
            counters.frames += len(missing)
            return np.ones(len(missing), dtype=bool)
        counters.corrupt += int(np.count_nonzero(missing == -2))
        late = missing == -1
        counters.duplicates += int(np.count_nonzero(late & repeated))
        counters.out_of_order += int(np.count_nonzero(late & ~repeated))
        gaps = missing > 0
        counters.gaps += int(np.count_nonzero(gaps))
        counters.missing += int(missing[gaps].sum())
        deliver = missing >= 0
        counters.frames += int(np.count_nonzero(deliver))
        return deliver


class ByteCodec(Codec[R]):
    """A codec for a byte stream whose frames start with a fixed sync word; it checks and unpacks many
    frames of one buffer at once (:meth:`parse`)."""

    sync: ClassVar[bytes]
    header_size: ClassVar[int]  # bytes from the sync word needed to know the frame length
    check_name: ClassVar[str] = "CRC"  # what :meth:`decode` says a frame failed
    sequence_modulus: ClassVar[int | None] = None  # None: the frame carries no counter
    sequence_step: int = 1  # counter steps between consecutive frames

    @property
    def counter_modulus(self) -> int | None:
        return self.sequence_modulus

    @abstractmethod
    def frame_lengths(self, buf: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """Total lengths (int64) of the frames whose headers (``header_size`` bytes, all present) start at
        ``starts`` in ``buf`` (uint8); 0 where the header is impossible."""

    @abstractmethod
    def parse(self, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(valid (N,) mask, the valid frames' fields as a structured array) of complete frames in ``buf``."""

    def count_items(self, rows: np.ndarray, counters: Counters) -> None:
        """Add what the delivered frames ``rows`` carried beside what is read to ``counters`` (a protocol whose
        frames carry optional items: ``counters.skipped_items``)."""

    def sequences(self, rows: np.ndarray) -> np.ndarray | None:
        """The frames' own counters (int64, -1 where a frame has none), or None for a protocol without."""
        return None

    def decode(self, frame: bytes) -> R:
        """The record of one complete frame; raises :class:`DecodeError` if it is not valid."""
        buf, at = np.frombuffer(frame, np.uint8), np.zeros(1, dtype=np.int64)
        if len(frame) < self.header_size or not frame.startswith(self.sync) or self.frame_lengths(buf, at)[0] != len(frame):
            raise DecodeError(f"{self.name}: expected a frame starting {self.sync.hex()} of the length its header gives")
        valid, rows = self.parse(buf, at, np.array([len(frame)]))
        if not valid[0]:
            raise DecodeError(f"{self.name}: {self.check_name} mismatch or malformed frame")
        return self.record(rows[0])

    def framer(self, time_scale: float | None = 1.0) -> ByteFramer:
        return ByteFramer(self, time_scale)


def fixed_rows(buf: np.ndarray, starts: np.ndarray, length: int) -> np.ndarray:
    """The ``length``-byte frames at ``starts`` as rows (N, length) of uint8."""
    return buf[starts[:, None] + np.arange(length)]


def sync_positions(buf: np.ndarray, sync: bytes) -> np.ndarray:
    """Every offset in ``buf`` (uint8) where the whole of ``sync`` starts."""
    last = len(buf) - len(sync)
    if last < 0:
        return np.zeros(0, dtype=np.int64)
    found = np.flatnonzero(buf[:last + 1] == sync[0])
    for k in range(1, len(sync)):
        found = found[buf[found + k] == sync[k]]
    return found


class ByteFramer(Framer):
    """Splits a byte stream into valid frames of one :class:`ByteCodec`."""

    def __init__(self, codec: ByteCodec, time_scale: float | None = 1.0) -> None:
        super().__init__()
        self.codec = codec
        self.unwrapper = SequenceUnwrapper(codec.sequence_modulus, host_rate(codec.rate_hz, time_scale),
                                           codec.sequence_step)
        self._buf = b""
        self._joined = False  # the buffer starts right after the last frame taken, no byte lost between

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def feed_chunk(self, chunk: RawChunk) -> FrameBatch:
        return self.feed_bytes(chunk.data, chunk.host_time)

    def feed_bytes(self, data: bytes, host_time: float = math.nan) -> FrameBatch:
        """The frames completed by ``data``, received at ``host_time``, as arrays."""
        codec, counters = self.codec, self.counters
        raw = self._buf + data
        buf = np.frombuffer(raw, np.uint8)
        end = len(buf)
        starts, lengths, rows, corrupt, stop = find_frames(codec, buf)
        counters.corrupt += corrupt
        if stop is None:
            last_end = int(starts[-1] + lengths[-1]) if len(starts) else 0
            stop = max(last_end, end - len(codec.sync) + 1, 0)
        ends = starts + lengths
        adjacent = np.concatenate(([self._joined and len(starts) > 0 and starts[0] == 0], starts[1:] == ends[:-1]))
        self._joined = bool(ends[-1] == stop) if len(starts) else self._joined and stop == 0
        rate = codec.rate_hz
        # A host that was held up reads a backlog at once: its frames left the device one period apart.
        sent = np.full(len(starts), host_time) if not rate else host_time - (end - ends) / lengths / rate
        index, missing, repeated = self.unwrapper.next_many(codec.sequences(rows), sent, adjacent[:len(starts)])
        deliver = self.unwrapper.count_many(counters, missing, repeated)
        sizes = lengths[deliver]
        counters.skipped_bytes += stop - int(sizes.sum())
        self._buf = raw[stop:]
        codec.count_items(rows[deliver], counters)
        return FrameBatch(rows[deliver], index[deliver], host_time, sizes)

    def reset(self) -> None:
        self.counters.skipped_bytes += len(self._buf)
        self._buf = b""
        self._joined = False


class Found(NamedTuple):
    """The valid frames :func:`find_frames` takes in a buffer, and what the search left."""

    starts: np.ndarray  # offsets (int64) of the frames taken, in order
    lengths: np.ndarray  # their lengths (int64)
    rows: np.ndarray  # their fields (the codec's structured array)
    corrupt: int  # candidates that failed their check
    stop: int | None  # offset where the search waits for more data, None when it found no open frame


def find_frames(codec: ByteCodec, buf: np.ndarray) -> Found:
    """The search of a :class:`ByteFramer` over ``buf`` (uint8): every sync word located at once, the frames
    behind them checked as arrays, then taken in order (see :func:`_walk`)."""
    end = len(buf)
    starts = sync_positions(buf, codec.sync)
    lengths = np.full(len(starts), -1, dtype=np.int64)  # -1: the header is still incomplete
    headed = starts + codec.header_size <= end
    lengths[headed] = codec.frame_lengths(buf, starts[headed])
    complete = (lengths > 0) & (starts + lengths <= end)
    valid = np.zeros(len(starts), dtype=bool)
    valid[complete], rows = codec.parse(buf, starts[complete], lengths[complete])
    taken, corrupt, stop = _walk(starts, lengths, complete, valid)
    rows = rows[np.searchsorted(np.flatnonzero(valid), taken)]
    return Found(starts[taken], lengths[taken], rows, corrupt, stop)


def _walk(starts: np.ndarray, lengths: np.ndarray, complete: np.ndarray, valid: np.ndarray
          ) -> tuple[np.ndarray, int, int | None]:
    """The candidates (sync words at ``starts``) the search takes, in order: (positions in ``starts`` of the
    frames taken, candidates counted corrupt, offset where the search waits for more data or None).

    From each frame taken the search goes on after it; a frame that fails its check is counted corrupt
    and the search goes on one byte after its sync word; an impossible header is skipped; an
    incomplete header or frame ends the search. Without overlaps (an undamaged stream) that is every
    complete candidate before the first incomplete one, found at once; else the candidates are walked."""
    m = len(starts)
    first_open = int(np.argmin(complete)) if m and not complete.all() else m
    ends = starts + lengths
    if (valid[:first_open].all() and (first_open == m or lengths[first_open] != 0)
            and (starts[1:first_open + 1] >= ends[:min(first_open, m - 1)]).all()):
        return np.arange(first_open), 0, None if first_open == m else int(starts[first_open])
    taken, corrupt, pos = [], 0, 0
    for k, (p, n, whole, ok) in enumerate(zip(starts.tolist(), lengths.tolist(), complete.tolist(), valid.tolist())):
        if p < pos:
            continue  # inside the frame taken last
        if not whole and n != 0:
            return np.array(taken, dtype=np.int64), corrupt, p
        if n == 0:
            continue
        if not ok:
            corrupt += 1
            continue
        taken.append(k)
        pos = p + n
    return np.array(taken, dtype=np.int64), corrupt, None
