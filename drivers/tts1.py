"""Turntable data ``tts1``: one 24-byte frame of sync-latched gimbal angles per external sync pulse."""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from pydantic import Field

from drivers.codec import FrameBatch
from drivers.crc import crc16_xmodem, crc_rows
from drivers.framing import ByteCodec, fixed_rows
from hil.config_types import Model
from hil.samples import TableSample, TableSamples
from hil.vocabulary import Stream

SYNC = b"\x54\x53\x01"  # sync word "TS" and version 1
FRAME_SIZE = 24
UDEG_PER_RAD = 180e6 / math.pi
FULL_TURN_UDEG = 360_000_000
_BODY = struct.Struct("<2sBBIiiiH")
_CRC = struct.Struct(">H")
FIELDS = np.dtype([("sync", "S3"), ("status", "u1"), ("sync_counter", "<u4"), ("angles_udeg", "<i4", 3),
                   ("latch_delay_us", "<u2"), ("crc", ">u2")])


class Status(enum.IntFlag):
    """Status byte bits 0-4; bits 5-7 hold the :class:`Mode`."""

    INTERLOCKS_CLOSED = 0x01
    MOVING = 0x02
    LIMIT_REACHED = 0x04
    FAULT = 0x08
    FREE_RUNNING = 0x10  # no external sync: frames paced by the table's own clock


class Mode(enum.IntEnum):
    OFF = 0
    POSITION = 1
    RATE = 2
    SYNTHESIS = 3


def status_byte(flags: Status, mode: Mode) -> int:
    """The status byte for flags and a mode."""
    return int(flags) | (int(mode) << 5)


def wrap_udeg(value: float) -> int:
    """An angle in micro-degrees, rounded and wrapped to [-180e6, 180e6)."""
    return (round(value) + FULL_TURN_UDEG // 2) % FULL_TURN_UDEG - FULL_TURN_UDEG // 2


@dataclass(frozen=True, slots=True)
class Tts1Frame:
    """One frame in device units: angles (outer, middle, inner) in 1e-6 deg, latch delay in us."""

    status: int
    sync_counter: int  # uint32, pulses since the output was enabled
    angles_udeg: tuple[int, int, int]
    latch_delay_us: int


class Tts1Options(Model):
    """n: the table latches every n-th pulse of the train it counts."""

    pulses_per_frame: int = Field(1, ge=1)


class Tts1Codec(ByteCodec[Tts1Frame]):
    """Encode and decode ``tts1`` frames; ``pulses_per_frame`` is n for a table that latches every n-th
    pulse of the train it counts (its counter steps by n from frame to frame)."""

    name: ClassVar[str] = "tts1"
    kind: ClassVar[str] = Stream.TABLE
    sync: ClassVar[bytes] = SYNC
    header_size: ClassVar[int] = len(SYNC)
    sequence_modulus: ClassVar[int] = 1 << 32

    Options: ClassVar[type[Model]] = Tts1Options

    def __init__(self, rate_hz: float | None = None, **options: Any) -> None:
        super().__init__(rate_hz, **options)
        self.sequence_step = self.options.pulses_per_frame

    def frame_lengths(self, buf: np.ndarray, starts: np.ndarray) -> np.ndarray:
        return np.full(len(starts), FRAME_SIZE, dtype=np.int64)

    def parse(self, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        frames = fixed_rows(buf, starts, FRAME_SIZE)
        rows = frames.view(FIELDS)[:, 0]
        valid = crc_rows(crc16_xmodem, frames[:, 2:22]) == rows["crc"]
        return valid, rows[valid]

    def record(self, row: Any) -> Tts1Frame:
        return Tts1Frame(int(row["status"]), int(row["sync_counter"]), tuple(row["angles_udeg"].tolist()),
                         int(row["latch_delay_us"]))

    def encode(self, record: Tts1Frame) -> bytes:
        body = _BODY.pack(SYNC[:2], SYNC[2], record.status, record.sync_counter & 0xFFFFFFFF,
                          *(wrap_udeg(a) for a in record.angles_udeg), record.latch_delay_us)
        return body + _CRC.pack(crc16_xmodem(body[2:]))

    def sequences(self, rows: np.ndarray) -> np.ndarray:
        return rows["sync_counter"].astype(np.int64)

    @staticmethod
    def si(angles_udeg: Any, latch_delay_us: Any) -> tuple[np.ndarray, np.ndarray]:
        """(angles rad, latch delay s) of device readings (angles (..., 3))."""
        return np.asarray(angles_udeg, dtype=float) / UDEG_PER_RAD, np.asarray(latch_delay_us, dtype=float) * 1e-6

    def samples(self, frames: FrameBatch) -> TableSamples:
        angles, delay = self.si(frames.rows["angles_udeg"], frames.rows["latch_delay_us"])
        return TableSamples(frames.sync_index, angles, np.full(len(frames), frames.host_time), delay,
                            frames.rows["status"].astype(np.int64))

    def from_sample(self, sample: TableSample) -> Tts1Frame:
        """The frame for an SI sample; the status byte is ``sample.status`` (see :func:`status_byte`)."""
        angles = tuple(wrap_udeg(a * UDEG_PER_RAD) for a in sample.angles)
        return Tts1Frame(sample.status, sample.sync_index & 0xFFFFFFFF, angles, round(sample.latch_delay * 1e6))

    def csv_header(self) -> list[str]:
        return ["status", "sync_counter", "outer_udeg", "middle_udeg", "inner_udeg", "latch_delay_us"]

    def csv_row(self, record: Tts1Frame) -> list[Any]:
        return [f"0x{record.status:02X}", record.sync_counter, *record.angles_udeg, record.latch_delay_us]
