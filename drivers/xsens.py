"""Xsens MTData2 over Xbus: ``FA FF 36 LEN payload CS`` with {XDI, size, data} items, big-endian."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Literal

import numpy as np

from drivers.codec import Counters, FrameBatch, HealthFlag
from drivers.xbus import EVERY_MESSAGE, MAX_PAYLOAD, OUTPUT_ITEMS, XsensConfigDialogue, item_kind
from drivers.framing import ByteCodec
from hil.config_types import Model
from hil.samples import ImuSample, ImuSamples
from hil.vocabulary import Stream

PREAMBLE = b"\xfa\xff\x36"  # preamble, bus id (master), message id MTData2
SAMPLE_TIME_HZ = 10_000.0  # SampleTimeFine ticks per second
MAX_OTHER = 32  # other items a message may carry that are counted by kind

SELF_TEST_PASSED = 0x1  # StatusWord bit 0: the MT passed its self-test
# StatusWord bit 0 (self-test passed) and the clipping flags of bits 8-13 (accelerometer x, y, z, gyro x, y, z)
HEALTH_FLAGS = (HealthFlag("self_test_failed", SELF_TEST_PASSED, valid_when_set=True),
                *(HealthFlag(f"clipping_{sensor}_{axis}", 1 << bit) for bit, (sensor, axis) in enumerate(
                    ((s, a) for s in ("accel", "gyro") for a in "xyz"), start=8)))

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class MtData2Frame:
    """The items of one MTData2 message (None when absent), in device units (SI, any precision on the wire)."""

    packet_counter: int | None = None  # uint16
    sample_time_fine: int | None = None  # uint32, 1e-4 s
    status_word: int | None = None  # uint32
    delta_q: tuple[float, float, float, float] | None = None  # quaternion increment (w, x, y, z)
    delta_v: Vec3 | None = None  # m/s
    acceleration: Vec3 | None = None  # m/s^2
    rate_of_turn: Vec3 | None = None  # rad/s
    status_byte: int | None = None  # uint8, the low byte of the status word
    temperature: float | None = None  # deg C, the sensor's (Temperature 0x0810)


# The low two bits of a data identifier select the precision of its numbers (MTData2 specification):
# name -> (bits, bytes per number).
PRECISIONS: dict[str, tuple[int, int]] = {"float32": (0, 4), "fp12.20": (1, 4), "fp16.32": (2, 6), "float64": (3, 8)}
_BYTES = {bits: size for bits, size in PRECISIONS.values()}
# Quantities in the sensor frame: identifier with the low nibble clear -> (record field, numbers).
VECTORS: dict[int, tuple[str, int]] = {0x8030: ("delta_q", 4), 0x4010: ("delta_v", 3), 0x4020: ("acceleration", 3),
                                       0x8020: ("rate_of_turn", 3), 0x0810: ("temperature", 1)}
# Counters and status: identifier -> (record field, struct).
SCALARS: dict[int, tuple[str, struct.Struct]] = {
    0x1020: ("packet_counter", struct.Struct(">H")),
    0x1060: ("sample_time_fine", struct.Struct(">I")),
    0xE010: ("status_byte", struct.Struct(">B")),
    0xE020: ("status_word", struct.Struct(">I")),
}
_XDI_OF = {name: xdi for xdi, (name, _) in {**VECTORS, **SCALARS}.items()}
_SCALAR_NAMES = tuple(name for name, _ in SCALARS.values())
# One message as a row: -1 for an absent counter or status, NaN for an absent vector; ``other`` lists the
# identifiers of the items not read (0 after the last).
FIELDS = np.dtype([("packet_counter", "i8"), ("sample_time_fine", "i8"), ("status_byte", "i8"), ("status_word", "i8"),
                   ("delta_q", "f8", 4), ("delta_v", "f8", 3), ("acceleration", "f8", 3), ("rate_of_turn", "f8", 3),
                   ("temperature", "f8", 1), ("other", "u2", MAX_OTHER)])
_VALUES = tuple(name for name in FIELDS.names if name != "other")
_EMPTY_ROW = {name: -1 if name in _SCALAR_NAMES else (math.nan,) * FIELDS[name].shape[0] for name in _VALUES}


def numbers(data: bytes, pos: int, count: int, bits: int) -> tuple[float, ...]:
    """``count`` numbers of precision ``bits`` at ``pos``: Float32, FP12.20 (int32 / 2^20), FP16.32 (a 48-bit
    fixed point sent as its 32-bit fraction, then its signed 16-bit integer part) or Float64; big-endian."""
    if bits == 0:
        return struct.unpack_from(f">{count}f", data, pos)
    if bits == 1:
        return tuple(v / 1048576.0 for v in struct.unpack_from(f">{count}i", data, pos))
    if bits == 2:
        parts = struct.unpack_from(">" + "Ih" * count, data, pos)
        return tuple(((parts[2 * k + 1] << 32) | parts[2 * k]) / 4294967296.0 for k in range(count))
    return struct.unpack_from(f">{count}d", data, pos)


def pack_numbers(values: Any, bits: int) -> bytes:
    """The wire form of ``values`` at precision ``bits`` (see :func:`numbers`); fixed point rounds to nearest."""
    if bits == 0:
        return struct.pack(f">{len(values)}f", *values)
    if bits == 3:
        return struct.pack(f">{len(values)}d", *values)
    scale, limit = (1 << 20, 1 << 31) if bits == 1 else (1 << 32, 1 << 47)
    raw = [round(v * scale) for v in values]
    if any(not -limit <= r < limit for r in raw):
        raise ValueError(f"xsens-mtdata2: {values} out of the range of {'FP12.20' if bits == 1 else 'FP16.32'}")
    if bits == 1:
        return struct.pack(f">{len(raw)}i", *raw)
    return b"".join(struct.pack(">Ih", r & 0xFFFFFFFF, r >> 32) for r in raw)


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
    other: list[int] = []
    pos, end = header, len(frame) - 1
    while pos < end:
        if end - pos < 3:
            return None  # truncated item header
        xdi, size = (frame[pos] << 8) | frame[pos + 1], frame[pos + 2]
        pos += 3
        if pos + size > end:
            return None  # the item overruns the payload
        vector, scalar = VECTORS.get(xdi & 0xFFF0 if not xdi & 0xC else -1), SCALARS.get(xdi)
        if vector is not None:
            name, count = vector
            if size != count * _BYTES[xdi & 0x3]:
                return None
            values[name] = numbers(frame, pos, count, xdi & 0x3)
        elif scalar is not None:
            name, layout = scalar
            if size != layout.size:
                return None
            values[name] = layout.unpack_from(frame, pos)[0]
        elif len(other) < MAX_OTHER:
            other.append(xdi)
        pos += size
    q = values.get("delta_q")
    if q is not None and not abs(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3] - 1.0) < 1e-5:
        return None  # the 8-bit checksum misses some multi-bit damage; a DeltaQ is always normalised
    return (*(values.get(name, _EMPTY_ROW[name]) for name in _VALUES), other + [0] * (MAX_OTHER - len(other)))


def rotation_vector_to_quaternion(v: Vec3) -> tuple[float, float, float, float]:
    """The unit quaternion (w, x, y, z) of a rotation vector (rad)."""
    angle = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    k = 0.5 if angle == 0.0 else math.sin(angle / 2.0) / angle
    return (math.cos(angle / 2.0), k * v[0], k * v[1], k * v[2])


class XsensOptions(Model):
    """The MTi's output configuration as the emulated device sends it (a real one is read in any precision)."""

    precision: Literal["float32", "fp12.20", "fp16.32", "float64"] = "float32"
    outputs: Literal["increments", "rates"] = "increments"  # DeltaQ and DeltaV, or RateOfTurn and Acceleration
    temperature: bool = False  # the Temperature item (0x0810) too
    check_config: bool = True  # ask the MTi for its output configuration before a trial (a read-only line: false)


class XsensCodec(ByteCodec[MtData2Frame]):
    """Encode and decode MTData2 messages; increments from DeltaQ/DeltaV or from rates at ``rate_hz``.

    Decoding reads every precision whatever ``precision`` says; ``precision`` and ``outputs`` ("increments":
    DeltaQ, DeltaV; "rates": RateOfTurn, Acceleration) are what :meth:`encode` sends (the emulated device's
    output configuration)."""

    name: ClassVar[str] = "xsens-mtdata2"
    kind: ClassVar[str] = Stream.IMU
    sync: ClassVar[bytes] = PREAMBLE
    header_size: ClassVar[int] = 6  # enough for the extended length
    sequence_modulus: ClassVar[int] = 1 << 16
    check_name: ClassVar[str] = "checksum"

    Options: ClassVar[type[Model]] = XsensOptions
    device_time: ClassVar[bool] = True
    healthy_status: ClassVar[int] = SELF_TEST_PASSED
    health_flags: ClassVar[tuple[HealthFlag, ...]] = HEALTH_FLAGS
    start_up_flags: ClassVar[tuple[str, ...]] = ("self_test_failed",)
    clip_flags: ClassVar[tuple[str, ...]] = ("clipping_gyro_x", "clipping_gyro_y", "clipping_gyro_z")

    def __init__(self, rate_hz: float, **options: Any) -> None:
        super().__init__(rate_hz, **options)
        self.precision, self.outputs = self.options.precision, self.options.outputs

    def config_dialogue(self) -> XsensConfigDialogue | None:
        return XsensConfigDialogue() if self.options.check_config else None

    def expected_config(self) -> dict[str, Any]:
        return {"imu.rate_hz": self.rate_hz, "imu.options.outputs": self.outputs}

    def output_configuration(self) -> list[tuple[int, int]]:
        """The (DataID, frequency) pairs of the items :meth:`encode` sends (the emulated MTi's configuration)."""
        bits = PRECISIONS[self.precision][0]
        hz = round(self.rate_hz)
        motion = [(xdi | bits, hz) for xdi in OUTPUT_ITEMS[self.outputs]]
        temperature = [(0x0810 | bits, hz)] if self.options.temperature else []
        return [(0x1020, EVERY_MESSAGE), (0x1060, EVERY_MESSAGE), (0xE020, EVERY_MESSAGE), *motion, *temperature]

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

    def count_items(self, rows: np.ndarray, counters: Counters) -> None:
        """The items the delivered messages carried beside those read, counted by kind."""
        other = rows["other"]
        kinds, counts = np.unique(other[other != 0], return_counts=True)
        for xdi, n in zip(kinds.tolist(), counts.tolist()):
            counters.skipped_items[item_kind(xdi)] = counters.skipped_items.get(item_kind(xdi), 0) + n

    def record(self, row: Any) -> MtData2Frame:
        values = {}
        for name in _VALUES:
            value = row[name]
            if name in _SCALAR_NAMES:
                values[name] = None if value < 0 else int(value)
            elif np.isnan(value[0]):
                values[name] = None
            else:
                values[name] = float(value[0]) if name == "temperature" else tuple(value.tolist())
        return MtData2Frame(**values)

    def encode(self, record: MtData2Frame) -> bytes:
        bits, size = PRECISIONS[self.precision]
        payload = bytearray()
        for name in _VALUES:
            value = getattr(record, name)
            if value is None:
                continue
            xdi = _XDI_OF[name]
            if name in _SCALAR_NAMES:
                payload += struct.pack(">HB", xdi, SCALARS[xdi][1].size) + SCALARS[xdi][1].pack(value)
            else:
                value = (value,) if name == "temperature" else value
                payload += struct.pack(">HB", xdi | bits, size * len(value)) + pack_numbers(value, bits)
        if len(payload) < 0xFF:
            message = PREAMBLE + bytes([len(payload)]) + payload
        else:
            message = PREAMBLE + b"\xff" + len(payload).to_bytes(2, "big") + payload
        return message + bytes([-sum(message[1:]) & 0xFF])

    def sequences(self, rows: np.ndarray) -> np.ndarray:
        return rows["packet_counter"]

    def increments(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dtheta (N, 3) rad, dv (N, 3) m/s, usable (N,)) of message rows: from DeltaQ and DeltaV where
        present, else from the rates over one sample (rectangle rule, see docs/devices.md); unusable where a
        message has neither."""
        dt = 1.0 / self.rate_hz
        q = rows["delta_q"]
        dtheta = np.where(np.isnan(q[:, :1]), rows["rate_of_turn"] * dt, rotation_vectors(q))
        dv = np.where(np.isnan(rows["delta_v"][:, :1]), rows["acceleration"] * dt, rows["delta_v"])
        return dtheta, dv, ~(np.isnan(dtheta[:, 0]) | np.isnan(dv[:, 0]))

    def status_words(self, rows: np.ndarray) -> np.ndarray:
        """The StatusWord, else the StatusByte (its low byte), else a healthy word (a message without a status
        says nothing is wrong)."""
        word, byte = rows["status_word"], rows["status_byte"]
        return np.where(word >= 0, word, np.where(byte >= 0, byte, self.healthy_status)).astype(np.int64)

    def samples(self, frames: FrameBatch) -> ImuSamples:
        """Messages with neither increments nor rates are left out (counted by the caller); the status is
        :meth:`status_words`', the temperature the Temperature item's (NaN without one)."""
        dtheta, dv, usable = self.increments(frames.rows)
        return ImuSamples(frames.sync_index, dtheta, dv, np.full(len(frames), frames.host_time),
                          self.status_words(frames.rows), frames.rows["temperature"][:, 0].copy()).take(usable)

    def from_sample(self, sample: ImuSample) -> MtData2Frame:
        """The message for an SI sample, with the items ``outputs`` names (and its temperature with ``temperature``)."""
        frame = MtData2Frame(
            packet_counter=sample.sync_index & 0xFFFF,
            sample_time_fine=None if sample.device_time is None
            else round(sample.device_time * SAMPLE_TIME_HZ) & 0xFFFFFFFF,
            status_word=self.sent_status(sample),
            temperature=sample.temperature_c if self.options.temperature and not math.isnan(sample.temperature_c)
            else None)
        if self.outputs == "increments":
            return replace(frame, delta_q=rotation_vector_to_quaternion(sample.dtheta), delta_v=sample.dv)
        return replace(frame, rate_of_turn=tuple(x * self.rate_hz for x in sample.dtheta),
                       acceleration=tuple(x * self.rate_hz for x in sample.dv))

    def csv_header(self) -> list[str]:
        return (["packet_counter", "sample_time_fine_100us", "status_byte", "status_word"]
                + [f"delta_q_{c}" for c in "wxyz"] + [f"delta_v_{c}_mps" for c in "xyz"]
                + [f"acc_{c}_mps2" for c in "xyz"] + [f"gyr_{c}_rad_s" for c in "xyz"] + ["temperature_c"])

    def csv_row(self, record: MtData2Frame) -> list[Any]:
        row: list[Any] = [record.packet_counter, record.sample_time_fine,
                          None if record.status_byte is None else f"0x{record.status_byte:02X}",
                          None if record.status_word is None else f"0x{record.status_word:08X}"]
        for value, n in ((record.delta_q, 4), (record.delta_v, 3), (record.acceleration, 3),
                         (record.rate_of_turn, 3)):
            row += list(value) if value is not None else [None] * n
        return [*row, record.temperature]
