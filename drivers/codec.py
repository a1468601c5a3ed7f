"""What every codec offers: frame records <-> wire, records -> SI samples, and a stream framer.

A codec is the plug-in for one protocol (see :mod:`drivers.registry`). Records keep the device's own
fields and units; :meth:`Codec.to_sample` converts to the SI records of :mod:`hil.samples` and
:meth:`Codec.from_sample` builds a record from SI values (the emulators encode with it).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np

from hil.samples import ImuSample, ImuSamples, TableSample, TableSamples

R = TypeVar("R")
Sample = ImuSample | TableSample


class DecodeError(ValueError):
    """Bytes or a frame that do not form a valid record of the protocol."""


@dataclass(frozen=True, slots=True)
class Decoded(Generic[R]):
    """A valid frame as it came off the wire: the device record, its unwrapped sync index, host time."""

    record: R
    sync_index: int
    host_time: float
    size: int  # bytes the frame occupied on the wire (CAN: payload bytes of all its messages)


@dataclass(frozen=True, slots=True)
class FrameBatch:
    """The valid frames of one read as arrays: the codec's fields (a structured array, one row a frame),
    their unwrapped sync indices (int64), the read's host time and the bytes each frame occupied."""

    rows: np.ndarray
    sync_index: np.ndarray
    host_time: float
    size: np.ndarray

    def __len__(self) -> int:
        return len(self.sync_index)


@dataclass(frozen=True, slots=True)
class RawChunk:
    """Whatever one read returned, good or bad, before any parsing: bytes, or one CAN frame."""

    stream: str
    host_time: float
    data: bytes
    arbitration_id: int | None = None  # CAN only
    is_extended_id: bool = False


@dataclass(frozen=True, slots=True)
class StreamEvent:
    """Something that happened to a stream's transport; a framer drops its partial frame on it."""

    stream: str
    host_time: float
    event: str  # "outage" or "reconnected"
    detail: str = ""


class Framer(ABC):
    """Turns raw chunks into decoded frames; never raises on bad input and counts what it dropped."""

    def __init__(self) -> None:
        self.counters = Counters()

    @abstractmethod
    def feed_chunk(self, chunk: RawChunk) -> list[Decoded]:
        """Decoded frames completed by this chunk."""

    def reset(self) -> None:
        """Forget a partial frame (after a reconnect); sequence continuity is kept."""


@dataclass
class Counters:
    """Running totals of one framer (mutable state, not a record)."""

    frames: int = 0  # valid frames decoded
    corrupt: int = 0  # frames that failed their CRC/checksum or structure check
    skipped_bytes: int = 0  # bytes that ended up in no valid frame
    gaps: int = 0  # jumps of the sequence counter by more than one
    missing: int = 0  # frames those jumps imply were lost
    duplicates: int = 0  # valid frames whose counter repeated the previous one (not delivered)
    out_of_order: int = 0  # valid frames that arrived after a later one (not delivered)
    skipped_items: dict[str, int] = field(default_factory=dict)  # data items of delivered frames not read, by kind

    def as_dict(self) -> dict[str, Any]:
        """The four headline counters, as ``hil decode`` prints them, and the items skipped by kind if any."""
        out: dict[str, Any] = {"frames": self.frames, "corrupt": self.corrupt, "skipped_bytes": self.skipped_bytes,
                               "gaps": self.gaps}
        return out | ({"skipped_items": dict(sorted(self.skipped_items.items()))} if self.skipped_items else {})


class Codec(ABC, Generic[R]):
    """One protocol: encode and decode its frames, convert them to SI samples."""

    name: ClassVar[str]
    kind: ClassVar[str]  # "imu" or "table"

    @abstractmethod
    def encode(self, record: R) -> Any:
        """The record on the wire (bytes, or CAN messages)."""

    @abstractmethod
    def framer(self, time_scale: float | None = 1.0) -> Framer:
        """A fresh stream framer for this codec; ``time_scale``: see :func:`drivers.framing.host_rate`."""

    @abstractmethod
    def to_sample(self, decoded: Decoded[R]) -> Sample:
        """The SI sample of a decoded frame."""

    def to_samples(self, decoded: list[Decoded[R]]) -> ImuSamples | TableSamples:
        """The SI samples of decoded frames, as arrays (a byte codec converts a :class:`FrameBatch` at once
        with ``samples``)."""
        samples = [self.to_sample(d) for d in decoded]
        return (ImuSamples if self.kind == "imu" else TableSamples).stack(samples)

    @abstractmethod
    def from_sample(self, sample: Any, **device_fields: Any) -> R:
        """A record carrying an SI sample (device-only fields such as temperature as keywords)."""

    @property
    def counter_modulus(self) -> int | None:
        """What the frames' sync counter counts modulo (None: the frames carry none)."""
        return None

    @abstractmethod
    def csv_header(self) -> list[str]:
        """Column names of :meth:`csv_row`, unit in each name; ``sync_index`` is added in front."""

    @abstractmethod
    def csv_row(self, record: R) -> list[Any]:
        """The record's fields in device units, in :meth:`csv_header` order."""


BITS_PER_BYTE = 10  # a serial line's 8N1
_PROBE = ImuSample(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), device_time=0.0)


def imu_frame_bytes(codec: Codec) -> int:
    """Bytes one IMU frame of ``codec`` takes on a serial line (0 for a codec whose frames are CAN messages)."""
    frame = codec.encode(codec.from_sample(_PROBE))
    return len(frame) if isinstance(frame, bytes) else 0
