"""Xsens MTData2 over Xbus: ``FA FF 36 LEN payload CS`` with {XDI, size, data} items, big-endian."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from drivers.codec import Decoded, DecodeError, FrameBatch
from drivers.framing import ByteCodec
from hil.samples import ImuSample, ImuSamples

PREAMBLE = b"\xfa\xff\x36"  # preamble, bus id (master), message id MTData2
MAX_PAYLOAD = 2048  # longer announced lengths are taken as a false sync
SAMPLE_TIME_HZ = 10_000.0  # SampleTimeFine ticks per second

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class MtData2Frame:
    """The items of one MTData2 message (None when absent), in device units (SI, float32 on the wire)."""

    packet_counter: int | None = None  # uint16
    sample_time_fine: int | None = None  # uint32, 1e-4 s
    status_word: int | None = None  # uint32
    delta_q: tuple[float, float, float, float] | None = None  # quaternion increment (w, x, y, z)
    delta_v: Vec3 | None = None  # m/s
    acceleration: Vec3 | None = None  # m/s^2
    rate_of_turn: Vec3 | None = None  # rad/s


# XDI -> (record field, struct of the data); float32 precision, ENU frame.
ITEMS: dict[int, tuple[str, struct.Struct]] = {
    0x1020: ("packet_counter", struct.Struct(">H")),
    0x1060: ("sample_time_fine", struct.Struct(">I")),
    0xE020: ("status_word", struct.Struct(">I")),
    0x8030: ("delta_q", struct.Struct(">4f")),
    0x4010: ("delta_v", struct.Struct(">3f")),
    0x4020: ("acceleration", struct.Struct(">3f")),
    0x8020: ("rate_of_turn", struct.Struct(">3f")),
}
_XDI_OF = {name: (xdi, s) for xdi, (name, s) in ITEMS.items()}
_SCALARS = ("packet_counter", "sample_time_fine", "status_word")
# One message as a row: -1 for an absent counter or word, NaN for an absent vector.
FIELDS = np.dtype([("packet_counter", "i8"), ("sample_time_fine", "i8"), ("status_word", "i8"),
                   ("delta_q", "f8", 4), ("delta_v", "f8", 3), ("acceleration", "f8", 3), ("rate_of_turn", "f8", 3)])
_EMPTY_ROW = tuple(-1 if name in _SCALARS else (math.nan,) * FIELDS[name].shape[0] for name in FIELDS.names)


def rotation_vectors(q: np.ndarray) -> np.ndarray:
    """The rotation vectors (N, 3) rad of (N, 4) unit quaternions (w, x, y, z)."""
    norm = np.sqrt(q[:, 1] ** 2 + q[:, 2] ** 2 + q[:, 3] ** 2)
    k = np.where(norm == 0.0, 0.0, 2.0 * np.arctan2(norm, q[:, 0]) / np.where(norm == 0.0, 1.0, norm))
    return k[:, None] * q[:, 1:]


def _items(frame: bytes) -> tuple | None:
    """The row (see FIELDS) of one complete message, or None if it is not valid."""
    header, length = (4, frame[3]) if frame[3] < 0xFF else (6, int.from_bytes(frame[4:6], "big"))
    if len(frame) != header + length + 1 or sum(frame, -frame[0]) & 0xFF:
        return None
    values: dict[str, Any] = {}
    pos, end = header, len(frame) - 1
    while pos < end:
        if end - pos < 3:
            return None  # truncated item header
        xdi, size = (frame[pos] << 8) | frame[pos + 1], frame[pos + 2]
        pos += 3
        if pos + size > end:
            return None  # the item overruns the payload
        item = ITEMS.get(xdi)
        if item is not None:
            name, layout = item
            if size != layout.size:
                return None
            data = layout.unpack_from(frame, pos)
            values[name] = data[0] if name in _SCALARS else data
        pos += size
    q = values.get("delta_q")
    if q is not None and not abs(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3] - 1.0) < 1e-5:
        return None  # the 8-bit checksum misses some multi-bit damage; a DeltaQ is always normalised
    return tuple(values.get(name, empty) for name, empty in zip(FIELDS.names, _EMPTY_ROW))


def rotation_vector_to_quaternion(v: Vec3) -> tuple[float, float, float, float]:
    """The unit quaternion (w, x, y, z) of a rotation vector (rad)."""
    angle = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    k = 0.5 if angle == 0.0 else math.sin(angle / 2.0) / angle
    return (math.cos(angle / 2.0), k * v[0], k * v[1], k * v[2])


class XsensCodec(ByteCodec[MtData2Frame]):
    """Encode and decode MTData2 messages; increments from DeltaQ/DeltaV or from rates at ``rate_hz``."""

    name: ClassVar[str] = "xsens-mtdata2"
    kind: ClassVar[str] = "imu"
    sync: ClassVar[bytes] = PREAMBLE
    header_size: ClassVar[int] = 6  # enough for the extended length
    sequence_modulus: ClassVar[int] = 1 << 16

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz

    @classmethod
    def from_config(cls, imu: Any, rate_hz: float) -> XsensCodec:
        return cls(rate_hz)

    check_name: ClassVar[str] = "checksum"

    def frame_lengths(self, buf: np.ndarray, starts: np.ndarray) -> np.ndarray:
        short = buf[starts + 3].astype(np.int64)
        extended = short == 0xFF
        lengths = 4 + short + 1
        if extended.any():
            at = starts[extended]
            payload = (buf[at + 4].astype(np.int64) << 8) | buf[at + 5]
            lengths[extended] = np.where(payload <= MAX_PAYLOAD, 6 + payload + 1, 0)
        return lengths

    def parse(self, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Messages carry any items in any order: each is checked and read on its own."""
        data = buf.tobytes()
        values = [_items(data[p:p + n]) for p, n in zip(starts.tolist(), lengths.tolist())]
        valid = np.array([v is not None for v in values], dtype=bool)
        return valid, np.array([v for v in values if v is not None], dtype=FIELDS)

    def record(self, row: Any) -> MtData2Frame:
        values = {}
        for name in FIELDS.names:
            value = row[name]
            if name in _SCALARS:
                values[name] = None if value < 0 else int(value)
            else:
                values[name] = None if np.isnan(value[0]) else tuple(value.tolist())
        return MtData2Frame(**values)

    def encode(self, record: MtData2Frame) -> bytes:
        payload = bytearray()
        for f in fields(record):
            value = getattr(record, f.name)
            if value is None:
                continue
            xdi, layout = _XDI_OF[f.name]
            payload += struct.pack(">HB", xdi, layout.size)
            payload += layout.pack(value) if f.name in _SCALARS else layout.pack(*value)
        if len(payload) < 0xFF:
            message = PREAMBLE + bytes([len(payload)]) + payload
        else:
            message = PREAMBLE + b"\xff" + len(payload).to_bytes(2, "big") + payload
        return message + bytes([-sum(message[1:]) & 0xFF])

    def sequence(self, record: MtData2Frame) -> int | None:
        return record.packet_counter

    def sequences(self, rows: np.ndarray) -> np.ndarray:
        return rows["packet_counter"]

    def increments(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dtheta (N, 3) rad, dv (N, 3) m/s, usable (N,)) of message rows: from DeltaQ and DeltaV where
        present, else from the rates over one sample; unusable where a message has neither."""
        dt = 1.0 / self.rate_hz
        q = rows["delta_q"]
        dtheta = np.where(np.isnan(q[:, :1]), rows["rate_of_turn"] * dt, rotation_vectors(q))
        dv = np.where(np.isnan(rows["delta_v"][:, :1]), rows["acceleration"] * dt, rows["delta_v"])
        return dtheta, dv, ~(np.isnan(dtheta[:, 0]) | np.isnan(dv[:, 0]))

    def samples(self, frames: FrameBatch) -> ImuSamples:
        """Messages with neither increments nor rates are left out (counted by the caller)."""
        dtheta, dv, usable = self.increments(frames.rows)
        status = np.maximum(frames.rows["status_word"], 0)
        return ImuSamples(frames.sync_index, dtheta, dv, np.full(len(frames), frames.host_time), status).take(usable)

    def to_sample(self, decoded: Decoded[MtData2Frame]) -> ImuSample:
        r = decoded.record
        row = np.array([tuple(_EMPTY_ROW[k] if getattr(r, name) is None else getattr(r, name)
                              for k, name in enumerate(FIELDS.names))], dtype=FIELDS)
        dtheta, dv, usable = self.increments(row)
        if not usable[0]:
            raise DecodeError("xsens-mtdata2: message has neither DeltaQ/DeltaV nor RateOfTurn/Acceleration")
        device_time = None if r.sample_time_fine is None else r.sample_time_fine / SAMPLE_TIME_HZ
        return ImuSample(decoded.sync_index, tuple(dtheta[0].tolist()), tuple(dv[0].tolist()), decoded.host_time,
                         device_time, r.status_word or 0)

    def from_sample(self, sample: ImuSample, outputs: str = "increments") -> MtData2Frame:
        """The message for an SI sample: ``outputs`` "increments" (DeltaQ, DeltaV) or "rates"."""
        frame = MtData2Frame(
            packet_counter=sample.sync_index & 0xFFFF,
            sample_time_fine=None if sample.device_time is None
            else round(sample.device_time * SAMPLE_TIME_HZ) & 0xFFFFFFFF,
            status_word=sample.status)
        if outputs == "increments":
            return replace(frame, delta_q=rotation_vector_to_quaternion(sample.dtheta), delta_v=sample.dv)
        if outputs == "rates":
            return replace(frame, rate_of_turn=tuple(x * self.rate_hz for x in sample.dtheta),
                           acceleration=tuple(x * self.rate_hz for x in sample.dv))
        raise ValueError(f"xsens-mtdata2: outputs must be 'increments' or 'rates', got {outputs!r}")

    def csv_header(self) -> list[str]:
        return (["packet_counter", "sample_time_fine_100us", "status_word"]
                + [f"delta_q_{c}" for c in "wxyz"] + [f"delta_v_{c}_mps" for c in "xyz"]
                + [f"acc_{c}_mps2" for c in "xyz"] + [f"gyr_{c}_rad_s" for c in "xyz"])

    def csv_row(self, record: MtData2Frame) -> list[Any]:
        row: list[Any] = [record.packet_counter, record.sample_time_fine,
                          None if record.status_word is None else f"0x{record.status_word:08X}"]
        for value, n in ((record.delta_q, 4), (record.delta_v, 3), (record.acceleration, 3),
                         (record.rate_of_turn, 3)):
            row += list(value) if value is not None else [None] * n
        return row
