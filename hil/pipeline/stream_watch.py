"""Whether each stream's bytes decode: bytes that keep arriving for ``output.stream_timeout_s`` without a frame
of the stream's codec give one line naming the port and what the bytes are (:mod:`drivers.detect`).

The watch is fed the chunks in their order with the stream's running frame count, and measures on the
chunks' host times, so a replay of the recorded chunks reaches the same verdict at the same chunk. It keeps
the last :data:`~drivers.detect.DETECT_BYTES` undecoded bytes of each stream for the detector.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from drivers.codec import RawChunk, StreamEvent
from drivers.detect import DETECT_BYTES, detect
from drivers.registry import IMU_CODECS
from hil.pipeline.processor import IMU, TABLE
from hil.pipeline.settings import PipelineSettings

SWAPPED = "are the IMU and table ports swapped?"


@dataclass(frozen=True, slots=True)
class Expected:
    """What a stream should carry, and the config keys its verdict names."""

    label: str  # "imu port", "turntable data port"
    kind: str  # the codec kind: "imu" or "table"
    protocol: str  # the configured codec
    protocol_key: str  # the key that chooses it (or the port)
    check: str  # the keys to check when nothing decodes

    @classmethod
    def of(cls, settings: PipelineSettings) -> dict[str, Expected]:
        """The IMU's and the table's."""
        imu = settings.imu
        check = ("imu.can.dbc and imu.can.signals" if IMU_CODECS.get(imu.protocol).link == "can"
                 else "imu.baudrate and imu.protocol")
        return {IMU: cls("imu port", IMU, imu.protocol, "imu.protocol", check),
                TABLE: cls("turntable data port", TABLE, settings.turntable.data_protocol, "turntable.data_protocol",
                           "turntable.baudrate and turntable.data_port")}


@dataclass(slots=True)
class _Undecoded:
    """A stream's bytes since its last frame (mutable state)."""

    frames: int = 0  # the stream's frame count when last fed
    since: float | None = None  # host time of the first chunk without a frame
    received: int = 0  # bytes (CAN: messages) since its last frame
    tail: bytearray = field(default_factory=bytearray)  # the last DETECT_BYTES of those bytes

    def clear(self) -> None:
        self.since, self.received = None, 0
        self.tail.clear()


class StreamWatch:
    """One verdict line once a stream's bytes have arrived for ``timeout_s`` (host time) without a frame."""

    def __init__(self, timeout_s: float, expected: dict[str, Expected], ports: dict[str, str]) -> None:
        self.timeout_s = timeout_s
        self.expected = expected
        self.ports = ports
        self._streams = {name: _Undecoded() for name in expected}

    @classmethod
    def of(cls, settings: PipelineSettings, ports: dict[str, str]) -> StreamWatch:
        """The watch of a pipeline's streams on ``ports`` (by stream name, as messages name them)."""
        return cls(settings.stream_timeout_s, Expected.of(settings), ports)

    def fed(self, chunk: RawChunk, frames: int) -> str | None:
        """Note a chunk the stream's decoder has taken, ``frames`` its frame count since the start; the verdict
        once the stream has gone ``timeout_s`` without a frame, else None."""
        state = self._streams.get(chunk.stream)
        if state is None or not chunk.data:
            return None
        if frames != state.frames:
            state.frames = frames
            state.clear()
            return None
        if state.since is None:
            state.since = chunk.host_time
        if chunk.arbitration_id is None:
            state.received += len(chunk.data)
            state.tail += chunk.data
            del state.tail[:-DETECT_BYTES]
        else:
            state.received += 1
        if chunk.host_time - state.since < self.timeout_s:
            return None
        return self._verdict(chunk.stream, state, chunk.arbitration_id is not None)

    def event(self, event: StreamEvent) -> None:
        """An outage or reconnection: the bytes after it are timed afresh."""
        if event.stream in self._streams:
            self._streams[event.stream].since = None

    def _verdict(self, stream: str, state: _Undecoded, can: bool) -> str:
        expected, port = self.expected[stream], self.ports[stream]
        found = None if can else detect(bytes(state.tail))
        if found is None or found.protocol == expected.protocol:
            unit = "CAN messages" if can else "bytes"
            return f"no frame in {state.received} {unit} on {port}: check {expected.check}"
        if found.kind != expected.kind:
            return f"the {expected.label} ({port}) carries {found.protocol} frames: {SWAPPED}"
        return f"the bytes on {port} decode as {found.protocol}, not {expected.protocol} ({expected.protocol_key})"
