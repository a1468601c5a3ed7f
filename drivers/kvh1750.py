"""KVH 1750 "format A": 36-byte big-endian frames with a CRC-32/MPEG-2 (docs/wire-formats.md, "KVH 1750"), and its
configuration mode's ASCII queries (docs/devices.md, "Configuration check")."""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np

from drivers.codec import FrameBatch, HealthFlag
from drivers.config_query import ConfigDialogue, DeviceConfig, Exchange, Setting, UnreadableReply
from drivers.crc import crc32_mpeg2, crc_rows
from drivers.framing import ByteCodec, fixed_rows
from hil.config_types import Model
from hil.samples import ImuSample, ImuSamples
from hil.vocabulary import Stream
from hil.units import G0

HEADER = b"\xfe\x81\xff\x55"
FRAME_SIZE = 36
STATUS_ALL_VALID = 0x77  # gyro x/y/z 0x01/0x02/0x04, accel x/y/z 0x10/0x20/0x40
# Each sensor's valid bit (clear: that sensor's output is not valid, as at power-up before the gyros settle)
HEALTH_FLAGS = tuple(HealthFlag(f"{sensor}_{axis}_invalid", bit << shift, valid_when_set=True)
                     for sensor, shift in (("gyro", 0), ("accel", 4)) for bit, axis in ((1, "x"), (2, "y"), (4, "z")))
_BODY = struct.Struct(">4s6fBBh")
_CRC = struct.Struct(">I")
FIELDS = np.dtype([("header", "S4"), ("gyro", ">f4", 3), ("accel", ">f4", 3), ("status", "u1"), ("sequence", "u1"),
                   ("temperature", ">i2"), ("crc", ">u4")])

Vec3 = tuple[float, float, float]

# Configuration mode (KVH 1750/1775 technical manual, "Commands and Queries"; TRECVT/ros_kvh1750 imu.cpp): ASCII
# lines ended by CR and/or LF; "=NAME,VALUE" sets and is answered "NAME,VALUE", "?NAME" is answered "NAME,VALUE".
# Normal mode streams frames and ignores every command but a few (=CONFIG,1 among them); configuration mode sends
# no frames and answers an unknown command "INVALID,<what it received>". Leaving it (=CONFIG,0) is not answered.
ENTER_CONFIG, LEAVE_CONFIG = "=CONFIG,1", "=CONFIG,0"
QUERIES = ("MSYNC", "DR", "ROTFMT", "ROTUNITS", "TEMPUNITS")  # MSYNC first: with EXT, DR is not the output rate
# A query's reply value -> the config key it sets and the value in the config's terms (DR: the rate, a number)
STATED: dict[str, tuple[str, dict[str, str]]] = {
    "ROTFMT": ("imu.options.gyro_output", {"DELTA": "delta", "RATE": "rate"}),
    "ROTUNITS": ("imu.options.gyro_unit", {"DEG": "deg", "RAD": "rad"}),
    "TEMPUNITS": ("imu.options.temperature_unit", {"C": "C", "F": "F"}),
}
# The values each reply may carry (DR: any rate); MSYNC: output timed by the IMU's clock at DR, or by the MSYNC input
ACCEPTED: dict[str, tuple[str, ...]] = {"CONFIG": ("1",), "MSYNC": ("IMU", "EXT"),
                                        **{name: tuple(table) for name, (_, table) in STATED.items()}}


def command_line(text: str) -> bytes:
    """A command or query as sent on the line."""
    return text.encode("ascii") + b"\r\n"


def reply_line(buf: bytes | bytearray, name: str) -> str | None:
    """The first whole line in ``buf`` answering ``name`` ("NAME,..." or "INVALID,..."), frames around it ignored;
    None until one has arrived up to its line end."""
    match = re.search(rb"(?:" + re.escape(name.encode("ascii")) + rb"|INVALID),[\x20-\x7e]*?(?=[\r\n])", buf)
    return None if match is None else match.group().decode("ascii")


class KvhConfigDialogue(ConfigDialogue):
    """=CONFIG,1, then each of :data:`QUERIES`, then =CONFIG,0 whatever happened."""

    def query(self, port: Exchange) -> DeviceConfig:
        replies: dict[str, str] = {}
        try:
            replies["CONFIG"] = self._ask(port, ENTER_CONFIG, "CONFIG", ACCEPTED["CONFIG"])
            for name in QUERIES:
                replies[name] = self._ask(port, "?" + name, name, ACCEPTED.get(name))
        finally:
            port.send(command_line(LEAVE_CONFIG))
        return DeviceConfig(replies, stated_settings(replies))

    @staticmethod
    def _ask(port: Exchange, request: str, name: str, values: tuple[str, ...] | None) -> str:
        """The device's reply to ``request``, checked: it answers ``name`` with one of ``values`` (None: a rate in
        Hz)."""
        reply = port.ask(command_line(request), lambda buf: reply_line(buf, name), f"{request!r}")
        value = reply.partition(",")[2].strip()
        readable = value in values if values is not None else re.fullmatch(r"\d+(\.\d+)?", value) and float(value) > 0
        if reply.startswith("INVALID,") or not readable:
            raise UnreadableReply(f"the KVH 1750 answers {request!r} with {reply!r}")
        return reply


def stated_settings(replies: dict[str, str]) -> tuple[Setting, ...]:
    """The config keys the checked replies set: the output rate (unless MSYNC says the output follows the external
    input), the gyro output and unit, the temperature unit."""
    values = {name: reply.partition(",")[2].strip() for name, reply in replies.items()}
    settings = [Setting(key, table[values[name]], replies[name]) for name, (key, table) in STATED.items()]
    if values["MSYNC"] == "IMU":
        settings.insert(0, Setting("imu.rate_hz", float(values["DR"]), replies["DR"]))
    return tuple(settings)


@dataclass(frozen=True, slots=True)
class KvhFrame:
    """One frame in device units: gyro per the IMU's setting (rad|deg, delta|rate), accel in g or m/s^2."""

    gyro: Vec3
    accel: Vec3
    status: int
    sequence: int  # 0..127
    temperature: int  # deg C, or deg F as the IMU's TEMPUNITS says


class Kvh1750Options(Model):
    """How the KVH 1750 itself is configured to output (its own settings, mirrored in ``imu.options``)."""

    gyro_unit: Literal["rad", "deg"] = "rad"
    gyro_output: Literal["delta", "rate"] = "delta"
    accel_unit: Literal["g", "m/s^2"] = "g"
    temperature_unit: Literal["C", "F"] = "C"  # its TEMPUNITS
    check_config: bool = True  # ask the IMU for its configuration before a trial (a read-only line: false)


class Kvh1750Codec(ByteCodec[KvhFrame]):
    """Encode and decode KVH 1750 frames; gyro and accel units follow the IMU's own configuration."""

    name: ClassVar[str] = "kvh1750"
    kind: ClassVar[str] = Stream.IMU
    sync: ClassVar[bytes] = HEADER
    header_size: ClassVar[int] = len(HEADER)
    sequence_modulus: ClassVar[int] = 128

    Options: ClassVar[type[Model]] = Kvh1750Options
    healthy_status: ClassVar[int] = STATUS_ALL_VALID
    health_flags: ClassVar[tuple[HealthFlag, ...]] = HEALTH_FLAGS
    start_up_flags: ClassVar[tuple[str, ...]] = ("gyro_x_invalid", "gyro_y_invalid", "gyro_z_invalid")  # status 0x70
    unit_keys: ClassVar[tuple[str, str, str]] = ("imu.options.accel_unit", "imu.options.gyro_unit",
                                                 "imu.options.gyro_output")

    def __init__(self, rate_hz: float, **options: Any) -> None:
        super().__init__(rate_hz, **options)
        self.gyro_unit, self.gyro_output, self.accel_unit = (self.options.gyro_unit, self.options.gyro_output,
                                                             self.options.accel_unit)
        dt = 1.0 / rate_hz
        # Device units -> rad and m/s over one sample interval.
        self._gyro_scale = (math.pi / 180.0 if self.gyro_unit == "deg" else 1.0) * (
            dt if self.gyro_output == "rate" else 1.0)
        self._accel_scale = (G0 if self.accel_unit == "g" else 1.0) * dt

    def frame_lengths(self, buf: np.ndarray, starts: np.ndarray) -> np.ndarray:
        return np.full(len(starts), FRAME_SIZE, dtype=np.int64)

    def config_dialogue(self) -> KvhConfigDialogue | None:
        return KvhConfigDialogue() if self.options.check_config else None

    def expected_config(self) -> dict[str, Any]:
        return {"imu.rate_hz": self.rate_hz, "imu.options.gyro_output": self.gyro_output,
                "imu.options.gyro_unit": self.gyro_unit, "imu.options.temperature_unit": self.options.temperature_unit}

    def stated_values(self) -> dict[str, str]:
        """What a KVH 1750 set up as this codec answers each of :data:`QUERIES` (the emulated device's replies)."""
        options = {"imu.options.gyro_output": self.gyro_output, "imu.options.gyro_unit": self.gyro_unit,
                   "imu.options.temperature_unit": self.options.temperature_unit}
        stated = {name: next(v for v, ours in table.items() if ours == options[key])
                  for name, (key, table) in STATED.items()}
        return {"MSYNC": "IMU", "DR": f"{self.rate_hz:g}", **stated}

    def parse(self, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        frames = fixed_rows(buf, starts, FRAME_SIZE)
        rows = frames.view(FIELDS)[:, 0]
        valid = crc_rows(crc32_mpeg2, frames[:, :32]) == rows["crc"]
        return valid, rows[valid]

    def record(self, row: Any) -> KvhFrame:
        return KvhFrame(tuple(row["gyro"].tolist()), tuple(row["accel"].tolist()), int(row["status"]),
                        int(row["sequence"]), int(row["temperature"]))

    def encode(self, record: KvhFrame) -> bytes:
        body = _BODY.pack(HEADER, *record.gyro, *record.accel, record.status, record.sequence & 0x7F,
                          record.temperature)
        return body + _CRC.pack(crc32_mpeg2(body))

    def sequences(self, rows: np.ndarray) -> np.ndarray:
        return rows["sequence"].astype(np.int64)

    def increments(self, gyro: np.ndarray, accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dtheta rad, dv m/s) of gyro and accel readings (..., 3) in device units."""
        return np.asarray(gyro, dtype=float) * self._gyro_scale, np.asarray(accel, dtype=float) * self._accel_scale

    def samples(self, frames: FrameBatch) -> ImuSamples:
        dtheta, dv = self.increments(frames.rows["gyro"], frames.rows["accel"])
        return ImuSamples(frames.sync_index, dtheta, dv, np.full(len(frames), frames.host_time),
                          frames.rows["status"].astype(np.int64), self.celsius(frames.rows["temperature"]))

    def celsius(self, temperature: np.ndarray) -> np.ndarray:
        """The frames' temperatures in deg C, from the unit the IMU sends."""
        t = np.asarray(temperature, dtype=float)
        return (t - 32.0) * (5.0 / 9.0) if self.options.temperature_unit == "F" else t

    def from_sample(self, sample: ImuSample) -> KvhFrame:
        """The frame for an SI sample; its status byte is ``sample.status`` (None: STATUS_ALL_VALID), its temperature
        ``sample.temperature_c`` to the nearest degree of the IMU's unit (25 deg C when it has none)."""
        g, a = self._gyro_scale, self._accel_scale
        celsius = 25.0 if math.isnan(sample.temperature_c) else sample.temperature_c
        return KvhFrame(tuple(x / g for x in sample.dtheta), tuple(x / a for x in sample.dv),
                        self.sent_status(sample), sample.sync_index % 128, round(self.device_temperature(celsius)))

    def device_temperature(self, celsius: float) -> float:
        """A temperature (deg C) in the unit the IMU sends."""
        return celsius * 9.0 / 5.0 + 32.0 if self.options.temperature_unit == "F" else celsius

    def csv_header(self) -> list[str]:
        gyro = self.gyro_unit + ("_s" if self.gyro_output == "rate" else "")
        accel = "g" if self.accel_unit == "g" else "mps2"
        return ([f"gyro_{c}_{gyro}" for c in "xyz"] + [f"accel_{c}_{accel}" for c in "xyz"]
                + ["status", "sequence", f"temperature_{self.options.temperature_unit.lower()}"])

    def csv_row(self, record: KvhFrame) -> list[Any]:
        return [*record.gyro, *record.accel, f"0x{record.status:02X}", record.sequence, record.temperature]
