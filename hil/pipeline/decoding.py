"""The decode stage: each stream's raw chunks and events into samples (SI), by that stream's
:class:`~drivers.decoder.StreamDecoder`."""

from __future__ import annotations

from drivers.codec import Codec, Counters, RawChunk, StreamEvent
from drivers.controllers import data_codec
from drivers.decoder import StreamDecoder
from drivers.registry import imu_codec
from hil.config import Config
from hil.pipeline.plausibility import UnitKeys
from hil.samples import ImuSamples, TableSamples

IMU, TABLE = "imu", "table"
Samples = ImuSamples | TableSamples


def stream_codecs(cfg: Config) -> dict[str, Codec]:
    """The codecs of the IMU's and the table's data streams, as the config sets them."""
    return {IMU: imu_codec(cfg.imu, cfg.imu_rate_hz), TABLE: data_codec(cfg.turntable, cfg.table_counts_per_frame)}


class Decoding:
    """The two streams' decoders. ``time_scale`` is the devices' speed (see :class:`~drivers.decoder.StreamDecoder`)."""

    def __init__(self, cfg: Config, time_scale: float | None) -> None:
        self.decoders = {stream: StreamDecoder(codec, time_scale, cfg.read_s)
                         for stream, codec in stream_codecs(cfg).items()}

    def codec(self, stream: str) -> Codec:
        return self.decoders[stream].codec

    def knows(self, stream: str) -> bool:
        """The trial reads this stream."""
        return stream in self.decoders

    def event(self, event: StreamEvent) -> Samples | None:
        """A reader's event on a known stream: the samples of the read before it (a message stream's tick
        still held), then the event to the decoder (an outage is counted)."""
        decoder = self.decoders[event.stream]
        held = decoder.flush()
        decoder.event(event)
        return held

    def chunk(self, chunk: RawChunk) -> Samples | None:
        """The samples of a known stream's chunk (None: none yet)."""
        return self.decoders[chunk.stream].feed(chunk)

    def flush(self) -> list[tuple[str, Samples | None]]:
        """End of data: every stream's samples still held."""
        return [(stream, decoder.flush()) for stream, decoder in self.decoders.items()]

    def counters(self, stream: str) -> Counters:
        """A stream's framer counters (frames, corrupt, missing, skipped bytes, gaps)."""
        return self.decoders[stream].counters

    def outages(self, stream: str) -> int:
        """A stream's ``outage`` events."""
        return self.decoders[stream].outages

    def frames(self) -> dict[str, int]:
        """Frames decoded per stream."""
        return {stream: decoder.counters.frames for stream, decoder in self.decoders.items()}

    def unit_keys(self) -> UnitKeys:
        """The config keys that set the IMU's units (for a diagnosis)."""
        return UnitKeys(*self.codec(IMU).unit_advice())
