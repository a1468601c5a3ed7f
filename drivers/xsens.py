"""Xsens MTData2 over Xbus: ``FA FF 36 LEN payload CS`` with {XDI, size, data} items, big-endian."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

from drivers.codec import Decoded, DecodeError
from drivers.framing import ByteCodec
from hil.samples import ImuSample

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


def quaternion_to_rotation_vector(q: tuple[float, float, float, float]) -> Vec3:
    """The rotation vector (rad) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    norm = math.sqrt(x * x + y * y + z * z)
    if norm == 0.0:
        return (0.0, 0.0, 0.0)
    k = 2.0 * math.atan2(norm, w) / norm
    return (k * x, k * y, k * z)


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

    def frame_length(self, buf: bytearray, start: int) -> int:
        length = buf[start + 3]
        if length < 0xFF:
            return 4 + length + 1
        length = (buf[start + 4] << 8) | buf[start + 5]
        return 6 + length + 1 if length <= MAX_PAYLOAD else 0

    def decode(self, frame: bytes) -> MtData2Frame:
        if len(frame) < 5 or not frame.startswith(PREAMBLE):
            raise DecodeError("xsens-mtdata2: expected FA FF 36 LEN")
        header, length = (4, frame[3]) if frame[3] < 0xFF else (6, int.from_bytes(frame[4:6], "big"))
        if len(frame) != header + length + 1:
            raise DecodeError("xsens-mtdata2: length does not match LEN")
        if sum(frame, -frame[0]) & 0xFF:
            raise DecodeError("xsens-mtdata2: checksum mismatch")
        values: dict[str, Any] = {}
        pos, end = header, len(frame) - 1
        while pos < end:
            if end - pos < 3:
                raise DecodeError("xsens-mtdata2: truncated item header")
            xdi, size = (frame[pos] << 8) | frame[pos + 1], frame[pos + 2]
            pos += 3
            if pos + size > end:
                raise DecodeError(f"xsens-mtdata2: item 0x{xdi:04X} overruns the payload")
            item = ITEMS.get(xdi)
            if item is not None:
                name, layout = item
                if size != layout.size:
                    raise DecodeError(f"xsens-mtdata2: item 0x{xdi:04X} has {size} bytes, expected {layout.size}")
                data = layout.unpack_from(frame, pos)
                values[name] = data[0] if name in _SCALARS else data
            pos += size
        q = values.get("delta_q")
        if q is not None and not abs(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3] - 1.0) < 1e-5:
            # The 8-bit checksum misses some multi-bit damage; a DeltaQ is always normalised.
            raise DecodeError("xsens-mtdata2: DeltaQ is not a unit quaternion")
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

    def to_sample(self, decoded: Decoded[MtData2Frame]) -> ImuSample:
        r, dt = decoded.record, 1.0 / self.rate_hz
        if r.delta_q is not None:
            dtheta = quaternion_to_rotation_vector(r.delta_q)
        elif r.rate_of_turn is not None:
            dtheta = tuple(w * dt for w in r.rate_of_turn)
        else:
            raise DecodeError("xsens-mtdata2: message has neither DeltaQ nor RateOfTurn")
        if r.delta_v is not None:
            dv = r.delta_v
        elif r.acceleration is not None:
            dv = tuple(a * dt for a in r.acceleration)
        else:
            raise DecodeError("xsens-mtdata2: message has neither DeltaV nor Acceleration")
        device_time = None if r.sample_time_fine is None else r.sample_time_fine / SAMPLE_TIME_HZ
        return ImuSample(decoded.sync_index, dtheta, dv, decoded.host_time, device_time, r.status_word or 0)

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
