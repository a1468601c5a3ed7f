"""The one decode loop: a stream's raw chunks -> framer -> codec -> samples, corrupt frames counted.

Used by the trial's processor (live and replay) and by ``hil decode``; a frame the codec rejects is
counted as corrupt and skipped, and the framer resynchronises on the bytes after it. A byte stream's
chunk becomes arrays at once: frames (:class:`~drivers.codec.FrameBatch`), then SI samples; a message stream's
chunks of one read tick do (:meth:`StreamDecoder.feed`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from drivers.codec import Codec, Counters, FrameBatch, Framer, RawChunk, StreamEvent
from hil.samples import ImuSamples, TableSamples
from hil.vocabulary import StreamEventKind


@dataclass
class StreamDecoder:
    """One stream's framer and codec, with its outage count: the stream's ``outage`` events, as the
    recording holds them, whether or not the device came back.

    ``time_scale`` is how much faster than real time the device runs (an emulator at ``--speed X``):
    the framer's counter unwrapping, which sizes outages longer than a counter period from the host
    receive times, then expects that many more frames per host second. None (``--speed max``): the
    host times say nothing about the device's, and only the counters are used.
    """

    codec: Codec
    time_scale: float | None = 1.0
    read_s: float | None = None
    framer: Framer = field(init=False)
    outages: int = 0
    _pending: list[FrameBatch] = field(init=False, default_factory=list)
    _tick: int | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.framer = self.codec.framer(self.time_scale)

    @property
    def counters(self) -> Counters:
        return self.framer.counters

    def frames(self, chunk: RawChunk) -> FrameBatch:
        """The complete frames of a chunk, still in device units (for captures)."""
        return self.framer.feed_chunk(chunk)

    def feed(self, chunk: RawChunk) -> ImuSamples | TableSamples | None:
        """The samples (SI) of a chunk's complete frames; frames that give no sample are counted corrupt.

        A message stream (CAN: a chunk a message) with ``read_s`` is read in ticks of ``read_s`` of the host's
        clock, as a byte stream's reader reads: the frames of the chunks received within one tick come out
        together, at the host time of the last, with the first chunk of a later tick (or :meth:`flush`); None
        until then."""
        if chunk.arbitration_id is None or self.read_s is None:
            return self._samples(self.framer.feed_chunk(chunk))
        tick = math.floor(chunk.host_time / self.read_s)
        ready = self.flush() if tick != self._tick else None
        self._tick = tick
        frames = self.framer.feed_chunk(chunk)
        if len(frames):
            self._pending.append(frames)
        return ready

    def flush(self) -> ImuSamples | TableSamples | None:
        """The samples of a message stream's tick still held (None: nothing held)."""
        if not self._pending:
            return None
        parts, self._pending = self._pending, []
        joined = FrameBatch(np.concatenate([p.rows for p in parts]), np.concatenate([p.sync_index for p in parts]),
                            parts[-1].host_time, np.concatenate([p.size for p in parts]))
        return self._samples(joined)

    def _samples(self, frames: FrameBatch) -> ImuSamples | TableSamples:
        samples = self.codec.samples(frames)
        self.framer.counters.corrupt += len(frames) - len(samples)
        return samples

    def event(self, event: StreamEvent) -> None:
        """A reader's event: an outage is counted; the framer forgets its partial frame."""
        self.outages += event.event == StreamEventKind.OUTAGE
        self.framer.reset()
