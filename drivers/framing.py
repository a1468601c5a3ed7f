"""Stream framing for byte protocols: find sync words, check frames, resynchronise, count.

Every byte fed ends up in exactly one of: a decoded frame, ``counters.skipped_bytes``, or the
buffer awaiting more data (:attr:`ByteFramer.buffered`). After a bad frame the search restarts one
byte after its sync word, so an intact frame that follows damage is always found.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from typing import ClassVar

from drivers.codec import Codec, Counters, Decoded, DecodeError, Framer, R, RawChunk


def host_rate(rate_hz: float | None, time_scale: float | None) -> float | None:
    """Frames per host second of a device at ``rate_hz`` running ``time_scale`` times faster than real
    time (an emulator at ``--speed X``); None when the host times say nothing of the device's (``--speed
    max``, or no known rate), so that only the counters are used."""
    return None if not rate_hz or time_scale is None else rate_hz * time_scale


class SequenceUnwrapper:
    """Unwraps a device counter that counts modulo ``modulus`` into a monotonic index.

    A counter that did not move is a repeated frame, and one that stepped back by at most
    ``REORDER_WINDOW`` frames is a late (out-of-order) frame: neither moves the index, and :meth:`next`
    marks them with a missing count of -1. Devices never repeat a number, so when the host receive
    times say that about a counter period or more has passed, the same readings are taken as wraps.
    With the device rate known, the host receive times also resolve wraps lost in an outage longer
    than the counter period (a 7-bit counter at 1 kHz wraps every 128 ms).

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

    def next(self, sequence: int | None, host_time: float) -> tuple[int, int]:
        """(index of this frame, frames missing since the previous one); missing is -1 for a repeated
        or late frame, whose index is then the earlier one it carries, and -2 for an implausible jump."""
        n = self.counts_per_frame
        if self._index is None:
            step = 0
            self._index = sequence if sequence is not None else 0
        elif sequence is None or self.modulus is None:
            step = n
        else:
            step = (sequence - self._sequence) % self.modulus
            host_counts = (host_time - self._time) * (self.rate_hz or math.nan) * n  # counts by the host clock
            timed = math.isfinite(host_counts)
            back = (self.modulus - step) % self.modulus
            if back <= min(self.REORDER_WINDOW * n, self.modulus // 4) and not (
                    timed and host_counts > self.modulus / 2):
                return self._index - back, -1
            step = step or self.modulus
            if timed:
                wraps = round((host_counts - step) / self.modulus)
                step += self.modulus * max(wraps, 0)
            limit = self.JUMP_LIMIT * n
            if step > limit and self.modulus > 4 * limit and not (timed and abs(host_counts - step) < limit):
                confirmed = self._suspect is not None and sequence == (self._suspect + n) % self.modulus
                if not confirmed:  # a frame whose damage the checksum missed, or a counter reset
                    self._suspect = sequence
                    return self._index, -2
        self._suspect = None
        self._index += step
        self._sequence = sequence if sequence is not None else 0
        self._time = host_time
        return self._index, max(round(step / n) - 1, 0)

    def count(self, counters: Counters, index: int, missing: int) -> bool:
        """Add a :meth:`next` outcome to ``counters``; False for a repeated, late or implausible frame
        (not to be delivered)."""
        if missing == -2:
            counters.corrupt += 1
            return False
        if missing < 0:
            if index == self._index:
                counters.duplicates += 1
            else:
                counters.out_of_order += 1
            return False
        if missing:
            counters.gaps += 1
            counters.missing += missing
        counters.frames += 1
        return True


class ByteCodec(Codec[R]):
    """A codec for a byte stream whose frames start with a fixed sync word."""

    sync: ClassVar[bytes]
    header_size: ClassVar[int]  # bytes from the sync word needed to know the frame length
    sequence_modulus: ClassVar[int | None] = None  # None: the frame carries no counter
    sequence_step: int = 1  # counter steps between consecutive frames
    rate_hz: float | None = None

    @abstractmethod
    def frame_length(self, buf: bytearray, start: int) -> int:
        """Total length of the frame whose header is at ``buf[start:]``; 0 if the header is impossible."""

    @abstractmethod
    def decode(self, frame: bytes) -> R:
        """The record of one complete frame; raises :class:`DecodeError` if it is not valid."""

    def sequence(self, record: R) -> int | None:
        """The frame's own counter, or None."""
        return None

    def framer(self, time_scale: float | None = 1.0) -> ByteFramer:
        return ByteFramer(self, time_scale)


class ByteFramer(Framer):
    """Splits a byte stream into valid frames of one :class:`ByteCodec`."""

    def __init__(self, codec: ByteCodec, time_scale: float | None = 1.0) -> None:
        super().__init__()
        self.codec = codec
        self.unwrapper = SequenceUnwrapper(codec.sequence_modulus, host_rate(codec.rate_hz, time_scale),
                                           codec.sequence_step)
        self._buf = bytearray()

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def feed_chunk(self, chunk: RawChunk) -> list[Decoded]:
        return self.feed(chunk.data, chunk.host_time)

    def _sent_at(self, host_time: float, bytes_from_frame: int, length: int) -> float:
        """When the device sent a frame that is followed by more bytes in the same read: a host that
        was held up reads a backlog at once, and the frames in it left the device one period apart."""
        rate = self.codec.rate_hz
        return host_time if not rate else host_time - (bytes_from_frame - length) / length / rate

    def feed(self, data: bytes, host_time: float = math.nan) -> list[Decoded]:
        """Decoded frames completed by ``data``, received at ``host_time``."""
        codec, counters, buf = self.codec, self.counters, self._buf
        buf += data
        sync, header_size = codec.sync, codec.header_size
        out: list[Decoded] = []
        pos, end = 0, len(buf)
        while True:
            start = buf.find(sync, pos)
            if start < 0:
                # Keep a tail that may be the beginning of a sync word.
                keep_from = max(pos, end - len(sync) + 1)
                counters.skipped_bytes += keep_from - pos
                pos = keep_from
                break
            counters.skipped_bytes += start - pos
            pos = start
            if end - start < header_size:
                break
            length = codec.frame_length(buf, start)
            if length <= 0:
                counters.skipped_bytes += 1
                pos += 1
                continue
            if end - start < length:
                break
            try:
                record = codec.decode(bytes(buf[start:start + length]))
            except DecodeError:
                counters.corrupt += 1
                counters.skipped_bytes += 1
                pos += 1
                continue
            index, missing = self.unwrapper.next(codec.sequence(record), self._sent_at(host_time, end - start, length))
            if self.unwrapper.count(counters, index, missing):
                out.append(Decoded(record, index, host_time, length))
            else:
                counters.skipped_bytes += length
            pos = start + length
        del buf[:pos]
        return out

    def reset(self) -> None:
        self.counters.skipped_bytes += len(self._buf)
        self._buf.clear()
