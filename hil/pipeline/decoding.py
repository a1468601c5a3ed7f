"""The decode stage: each stream's raw chunks and events into samples (SI), by that stream's
:class:`~drivers.decoder.StreamDecoder`; the IMU's frame rate measured on the receive times against
``imu.rate_hz`` (:class:`FrameRate`), and its temperature (:class:`~hil.pipeline.temperature.TemperatureTrack`)."""

from __future__ import annotations

from drivers.codec import Codec, Counters, RawChunk, StreamEvent
from drivers.decoder import StreamDecoder
from hil.pipeline.plausibility import UnitKeys
from hil.pipeline.settings import PipelineSettings
from hil.pipeline.temperature import TemperatureTrack
from hil.samples import ImuSamples, TableSamples
from hil.vocabulary import Stream

IMU, TABLE = Stream.IMU, Stream.TABLE
Samples = ImuSamples | TableSamples
RATE_WINDOW_S = 2.0  # s of the devices' time over which the IMU's frame rate is measured, once, ...
RATE_HOST_S = 1.0  # ... and at least this long on the host's clock (a fast emulator's reads jitter alike)
RATE_TOLERANCE = 0.05  # the measured rate may differ from imu.rate_hz by this fraction
RATE_CLEAR = 0.2  # a rate this far off is another setting of the device, judged on the first window; one nearer
RATE_CONFIRM_HOST_S = 6.0  # is measured over this much of the host's clock at least, where a stall weighs less


class FrameRate:
    """The IMU's frame rate on the receive times: the frames decoded from the end of the first read that had some
    (a port whose bytes decode to nothing is the stream watch's: :mod:`hil.pipeline.stream_watch`) over the next
    ``RATE_WINDOW_S`` of the devices' time (the host's times the devices' speed ``time_scale``, and ``RATE_HOST_S``
    of the host's), judged once against ``rate_hz``. A gap of the IMU's counter (frames lost, a power cycle's
    silence) or an outage starts the window again at the read: only a stream that lost nothing is judged. At
        ``--speed max`` (None) the host times say nothing of the devices' rate: nothing is judged. A rate off by less
    than ``RATE_CLEAR`` (the output rates IMUs offer lie further apart) is judged only on ``RATE_CONFIRM_HOST_S`` of
    the host's clock, so that a host or an emulator stalled for a moment never ends a trial naming a wrong rate."""

    def __init__(self, rate_hz: float, time_scale: float | None) -> None:
        self.rate_hz, self.time_scale = rate_hz, time_scale
        self._start: tuple[float, int, int] | None = None  # (host time, frames, gaps) at the window's start
        self.judged = time_scale is None
        self.mismatch: str | None = None

    def fed(self, host_time: float, frames: int, gaps: int) -> None:
        """A read of the IMU's stream at ``host_time``: the frames decoded and the counter's gaps so far."""
        if self.judged or not frames:
            return
        if self._start is None or gaps != self._start[2]:
            self._start = (host_time, frames, gaps)
            return
        host = host_time - self._start[0]
        span = host * self.time_scale
        if span < RATE_WINDOW_S or host < RATE_HOST_S:
            return
        measured = (frames - self._start[1]) / span
        off = abs(measured / self.rate_hz - 1.0)
        if RATE_TOLERANCE < off < RATE_CLEAR and host < RATE_CONFIRM_HOST_S:
            return  # a loaded host or emulator that stalled for a tenth of a second would look like this
        self.judged = True
        if off > RATE_TOLERANCE:
            self.mismatch = (f"the IMU sends {measured:.4g} frames/s but imu.rate_hz is {self.rate_hz:g} Hz: set "
                             "imu.rate_hz to the IMU's output rate (or the IMU to the configured rate)")

    def restart(self) -> None:
        """An outage: the window starts again at the next read."""
        self._start = None


class Decoding:
    """The two streams' decoders. ``time_scale`` is the devices' speed (see :class:`~drivers.decoder.StreamDecoder`)."""

    def __init__(self, settings: PipelineSettings, time_scale: float | None) -> None:
        self.decoders = {stream: StreamDecoder(codec, time_scale, settings.read_s)
                         for stream, codec in settings.codecs().items()}
        self.imu_rate = FrameRate(settings.imu_rate_hz, time_scale)
        self.temperature = TemperatureTrack()

    def codec(self, stream: str) -> Codec:
        return self.decoders[stream].codec

    def knows(self, stream: str) -> bool:
        """The trial reads this stream."""
        return stream in self.decoders

    def event(self, event: StreamEvent) -> Samples | None:
        """A reader's event on a known stream: the samples of the read before it (a message stream's tick
        still held), then the event to the decoder (an outage is counted)."""
        decoder = self.decoders[event.stream]
        held = self._taken(event.stream, decoder.flush())
        decoder.event(event)
        if event.stream == IMU:
            self.imu_rate.restart()
        return held

    def chunk(self, chunk: RawChunk) -> Samples | None:
        """The samples of a known stream's chunk (None: none yet)."""
        samples = self.decoders[chunk.stream].feed(chunk)
        if chunk.stream == IMU:
            counters = self.decoders[IMU].counters
            self.imu_rate.fed(chunk.host_time, counters.frames, counters.gaps)
        return self._taken(chunk.stream, samples)

    def flush(self) -> list[tuple[str, Samples | None]]:
        """End of data: every stream's samples still held."""
        return [(stream, self._taken(stream, decoder.flush())) for stream, decoder in self.decoders.items()]

    def _taken(self, stream: str, samples: Samples | None) -> Samples | None:
        """Samples on their way out: the IMU's temperatures to the track."""
        if stream == IMU and samples is not None:
            self.temperature.add(samples.temperature_c)
        return samples

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
