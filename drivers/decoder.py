"""The one decode loop: a stream's raw chunks -> framer -> codec -> samples, corrupt frames counted.

Used by the trial's processor (live and replay) and by ``hil decode``; a frame the codec rejects is
counted as corrupt and skipped, and the framer resynchronises on the bytes after it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from drivers.codec import (
    Codec,
    Counters,
    Decoded,
    DecodeError,
    Framer,
    RawChunk,
    StreamEvent,
)


@dataclass
class StreamDecoder:
    """One stream's framer and codec, with its outage count: outages after which the device sent data
    again (a port closing at the end of a trial, or a reconnection to nothing, is not one).

    ``time_scale`` is how much faster than real time the device runs (an emulator at ``--speed X``):
    the framer's counter unwrapping, which sizes outages longer than a counter period from the host
    receive times, then expects that many more frames per host second. None (``--speed max``): the
    host times say nothing about the device's, and only the counters are used.
    """

    codec: Codec
    time_scale: float | None = 1.0
    framer: Framer = field(init=False)
    outages: int = 0
    _reconnects: int = 0  # reconnections not yet followed by data

    def __post_init__(self) -> None:
        self.framer = self.codec.framer(self.time_scale)

    @property
    def counters(self) -> Counters:
        return self.framer.counters

    def frames(self, chunk: RawChunk) -> list[Decoded]:
        """The complete frames of a chunk, still in device units (for captures)."""
        if chunk.data:
            self.outages += self._reconnects  # the device is back: the outages before count
            self._reconnects = 0
        return self.framer.feed_chunk(chunk)

    def feed(self, chunk: RawChunk) -> list[Any]:
        """The samples (SI) of a chunk's complete frames."""
        samples = []
        for decoded in self.frames(chunk):
            try:
                samples.append(self.codec.to_sample(decoded))
            except DecodeError:
                self.framer.counters.corrupt += 1
        return samples

    def event(self, event: StreamEvent) -> None:
        if event.event == "reconnected":
            self._reconnects += 1
        self.framer.reset()
