"""What every codec offers, declared once with its defaults (as python-can's ``BusABC``): built from the
IMU's rate and its own options, a stream framer that gives a read's frames as arrays, their SI samples,
records <-> wire for the emulator, and what the harness asks of a device (counter modulus, frame size,
status of a healthy device, the keys that set its units).

A codec is the plug-in for one protocol (found by name: :mod:`drivers.registry`). Records keep the device's own
fields and units; :meth:`Codec.samples` converts a batch of frames to the SI arrays of :mod:`hil.samples`
and :meth:`Codec.from_sample` builds a record from SI values (the emulators encode with it).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar

import numpy as np

from hil.config_types import Model
from hil.inputs import ConfigError
from hil.samples import ImuSample, ImuSamples, TableSample, TableSamples
from hil.vocabulary import Stream, StreamEventKind

if TYPE_CHECKING:
    from drivers.config_query import ConfigDialogue

R = TypeVar("R")


class DecodeError(ValueError):
    """Bytes or a frame that do not form a valid record of the protocol."""


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
    event: StreamEventKind
    detail: str = ""


class Framer(ABC):
    """Turns raw chunks into decoded frames; never raises on bad input and counts what it dropped."""

    def __init__(self) -> None:
        self.counters = Counters()

    @abstractmethod
    def feed_chunk(self, chunk: RawChunk) -> FrameBatch:
        """The valid frames completed by this chunk."""

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


@dataclass(frozen=True, slots=True)
class HealthFlag:
    """One of a device's status bits that marks its sample invalid: ``name`` (result.json's
    ``streams.imu_invalid_by_flag`` counts by it), the ``mask`` of the status word, and whether the bit says the
    sample is good (``valid_when_set``, as the KVH 1750's valid bits) or reports a fault (set: invalid)."""

    name: str
    mask: int
    valid_when_set: bool = False

    def raised(self, status: np.ndarray) -> np.ndarray:
        """Per status word (N,), True where this flag marks the sample invalid."""
        hit = (np.asarray(status, dtype=np.int64) & self.mask) != 0
        return ~hit if self.valid_when_set else hit


def raised_flags(flags: tuple[HealthFlag, ...], status: np.ndarray) -> np.ndarray:
    """Per status word (N,), which of ``flags`` mark the sample invalid: (N, len(flags)) bool."""
    status = np.asarray(status, dtype=np.int64)
    return np.stack([flag.raised(status) for flag in flags], axis=1) if flags \
        else np.zeros((len(status), 0), dtype=bool)


class NoOptions(Model):
    """The options of a codec that has none (``imu.options`` must then be empty)."""


class Codec(ABC, Generic[R]):
    """One protocol: encode and decode its frames, convert them to SI samples.

    Built as ``cls(rate_hz, **options)``: ``options`` are validated by the codec's :attr:`Options` model (a
    pydantic model; what the device's own output settings are, the ``imu.options`` of the config), and the
    validated model is ``self.options``. A subclass that derives more from them extends ``__init__``.
    """

    name: ClassVar[str]
    kind: ClassVar[str]  # the stream it decodes: Stream.IMU or Stream.TABLE
    Options: ClassVar[type[Model]] = NoOptions
    link: ClassVar[str] = "serial"  # "serial": frames are bytes on a line (baud checked); "can": CAN messages
    healthy_status: ClassVar[int] = 0  # the status word of a device with nothing to report (the emulator sends it)
    # The status bits that mark a sample invalid (docs/devices.md, "Health flags"); none: every sample is valid.
    health_flags: ClassVar[tuple[HealthFlag, ...]] = ()
    start_up_flags: ClassVar[tuple[str, ...]] = ()  # those it raises while it starts (the emulator's flagged samples)
    clip_flags: ClassVar[tuple[str, ...]] = ()  # those it raises for a gyro x, y, z reading its range (none: no such)
    device_time: ClassVar[bool] = False  # the frames carry the device's own clock (the emulator fills it in)
    # The config keys that set the accelerometer unit, the gyro unit and the gyro output (rate or increment),
    # which the plausibility check names when the readings are off by a unit; None: the protocol fixes them.
    unit_keys: ClassVar[tuple[str, str, str] | None] = None

    def __init__(self, rate_hz: float | None = None, **options: Any) -> None:
        """``rate_hz``: the device's output rate (None for a protocol that does not need it)."""
        self.rate_hz = rate_hz
        self.options = self.Options(**options)

    @classmethod
    def from_config(cls, imu: Any, rate_hz: float) -> Codec:
        """The codec an ``imu`` config block (:class:`hil.config.ImuConfig`) asks for, at ``rate_hz``."""
        return cls(rate_hz, **imu.options)

    @abstractmethod
    def encode(self, record: R) -> Any:
        """The record on the wire (bytes, or CAN messages)."""

    @abstractmethod
    def framer(self, time_scale: float | None = 1.0) -> Framer:
        """A fresh stream framer for this codec; ``time_scale``: see :func:`drivers.framing.host_rate`."""

    @abstractmethod
    def record(self, row: Any) -> R:
        """The record of one row of a :class:`FrameBatch` (``hil decode`` writes records)."""

    @abstractmethod
    def samples(self, frames: FrameBatch) -> ImuSamples | TableSamples:
        """The SI samples of a batch of frames; a frame that gives no sample is left out (counted corrupt by
        the caller)."""

    @abstractmethod
    def from_sample(self, sample: Any) -> R:
        """The record carrying an SI sample (the emulated device's output)."""

    @property
    def counter_modulus(self) -> int | None:
        """What the frames' sync counter counts modulo (None: the frames carry none)."""
        return None

    def sent_status(self, sample: ImuSample) -> int:
        """The status word a frame carrying ``sample`` sends: its own, else a healthy device's."""
        return self.healthy_status if sample.status is None else sample.status

    def flagged_status(self, names: tuple[str, ...]) -> int:
        """The healthy status word with the health flags ``names`` raised (a valid bit cleared, a fault bit set)."""
        status = self.healthy_status
        for flag in self.health_flags:
            if flag.name in names:
                status = status & ~flag.mask if flag.valid_when_set else status | flag.mask
        return status

    def status_words(self, rows: np.ndarray) -> np.ndarray:
        """The status word (int64) of each row of a :class:`FrameBatch`: its ``status`` field (0 without one);
        a codec whose frames hold their status otherwise says how."""
        names = rows.dtype.names or ()
        return rows["status"].astype(np.int64) if "status" in names else np.zeros(len(rows), dtype=np.int64)

    def frame_bytes(self) -> int:
        """Bytes one frame takes on a serial line, for the baud check (0 for frames that are CAN messages)."""
        if self.link != "serial":
            return 0
        probe = (ImuSample(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), device_time=0.0, status=self.healthy_status)
                 if self.kind == Stream.IMU
                 else TableSample(1, (0.0, 0.0, 0.0)))
        return len(self.encode(self.from_sample(probe)))

    def config_dialogue(self) -> ConfigDialogue | None:
        """How the harness asks the device for its configuration before a trial (:mod:`drivers.config_query`);
        None: the protocol has no such query (or ``imu.options.check_config`` is false)."""
        return None

    def expected_config(self) -> dict[str, Any]:
        """The config keys the device's own configuration is compared with, and their values in this config."""
        return {}

    def unit_advice(self) -> tuple[str, str, str]:
        """What to check when the readings are off by a unit: the keys of :attr:`unit_keys`, else the protocol."""
        return self.unit_keys or (f"imu.protocol ({self.name})",) * 3

    @abstractmethod
    def csv_header(self) -> list[str]:
        """Column names of :meth:`csv_row`, unit in each name; ``sync_index`` is added in front."""

    @abstractmethod
    def csv_row(self, record: R) -> list[Any]:
        """The record's fields in device units, in :meth:`csv_header` order."""


BITS_PER_BYTE = 10  # a serial line's 8N1


def check_baudrate(name: str, frame_bytes: int, rate_hz: float, baudrate: int) -> None:
    """Raise :class:`ConfigError` naming ``<name>.baudrate`` when frames of ``frame_bytes`` at ``rate_hz`` do not
    fit the serial line (8N1): the device could not send them, or is not set as the config says."""
    needed = frame_bytes * BITS_PER_BYTE * rate_hz
    if needed > baudrate:
        raise ConfigError(f"{name}.baudrate: {frame_bytes}-byte frames at {rate_hz:g} Hz need {needed:.0f} baud "
                          f"(8N1), more than the configured {baudrate}; raise the baudrate or lower the rate")
