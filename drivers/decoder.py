"""The one decode loop: a stream's raw chunks -> framer -> codec -> samples, corrupt frames counted.

Used by the trial's processor (live and replay) and by ``hil decode``; a frame the codec rejects is
counted as corrupt and skipped, and the framer resynchronises on the bytes after it. A byte stream's
chunk becomes arrays at once: frames (:class:`~drivers.codec.FrameBatch`), then SI samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from drivers.codec import Codec, Counters, FrameBatch, Framer, RawChunk, StreamEvent
from hil.samples import ImuSamples, TableSamples


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
    framer: Framer = field(init=False)
    outages: int = 0

    def __post_init__(self) -> None:
        self.framer = self.codec.framer(self.time_scale)

    @property
    def counters(self) -> Counters:
        return self.framer.counters

    def frames(self, chunk: RawChunk) -> FrameBatch:
        """The complete frames of a chunk, still in device units (for captures)."""
        return self.framer.feed_chunk(chunk)

    def feed(self, chunk: RawChunk) -> ImuSamples | TableSamples:
        """The samples (SI) of a chunk's complete frames; frames that give no sample are counted corrupt."""
        frames = self.framer.feed_chunk(chunk)
        samples = self.codec.samples(frames)
        self.framer.counters.corrupt += len(frames) - len(samples)
        return samples

    def event(self, event: StreamEvent) -> None:
        """A reader's event: an outage is counted; the framer forgets its partial frame."""
        self.outages += event.event == "outage"
        self.framer.reset()
