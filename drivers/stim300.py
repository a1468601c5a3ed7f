"""Sensonor STIM300 normal-mode datagrams (datasheet TS1524, sections 5.5.6, 5.5.7, 5.6 and 7.5.2.2).

A datagram is its identifier byte, then per sensor cluster three 24-bit big-endian two's-complement
outputs and a status byte (gyros, accelerometers, inclinometers if chosen), the temperatures if chosen
(three 16-bit values and a status byte per cluster sent), an 8-bit counter of the 2000/s internal
samples, a 16-bit latency in microseconds and a CRC-32 (poly 0x04C11DB7, seed 0xFFFFFFFF, no reflection)
over everything before it plus the zero dummy bytes that make that a whole number of 32-bit words.
The datagram, the output units and the accelerometer range are the device's settings (``imu.options``);
the datagrams without accelerometers carry no increments the harness can use and are not offered.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np

from drivers.codec import FrameBatch, HealthFlag
from drivers.crc import crc32_mpeg2, crc_rows
from drivers.framing import ByteCodec, fixed_rows
from hil.config_types import Model
from hil.samples import ImuSample, ImuSamples
from hil.vocabulary import Stream
from hil.units import G0

INTERNAL_HZ = 2000  # the counter counts internal samples at this rate
# identifier -> (inclinometers, temperatures, dummy bytes for the CRC), Tables 5-21 and 5-22
DATAGRAMS: dict[int, tuple[bool, bool, int]] = {0x91: (False, False, 0), 0x93: (True, False, 2),
                                                0xA5: (False, True, 2), 0xA7: (True, True, 1)}
TEMP_LSB = 256.0  # counts per deg C of a temperature field (Equation 9)
GYRO_LSB = {"rate": 2.0 ** -14, "increment": 2.0 ** -21}  # deg/s or deg per bit (Equations 1 and 2)
# accelerometer range (g) -> bits of the fraction: acceleration (g, Equation 3), increment (m/s, Equation 4)
ACCEL_FRACTION = {5: (20, 23), 10: (19, 22), 30: (18, 21), 80: (16, 19)}
FIELDS = np.dtype([("gyro", "i4", 3), ("accel", "i4", 3), ("gyro_status", "u1"), ("accel_status", "u1"),
                   ("incl_status", "u1"), ("gyro_temp", "i2", 3), ("accel_temp", "i2", 3), ("counter", "u1"),
                   ("latency_us", "u2")])

# A cluster's status byte (Table 5-23): bit 7 system integrity error, 6 start-up, 5 outside operating conditions,
# 4 overload, 3 channel error (bits 0-2 name the axis of the last two); the gyros' in the status word's low byte,
# the accelerometers' in the next (the inclinometers', unused, above)
STATUS_BITS = (("system_integrity_error", 0x80), ("start_up", 0x40), ("outside_operating_conditions", 0x20),
               ("overload", 0x10), ("channel_error", 0x08))
HEALTH_FLAGS = tuple(HealthFlag(f"{cluster}_{name}", bit << shift) for cluster, shift in (("gyro", 0), ("accel", 8))
                     for name, bit in STATUS_BITS)

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class StimDatagram:
    """One datagram's gyro and accelerometer outputs (raw 24-bit counts), status bytes, temperatures (raw
    1/256 deg C, zero when not sent), counter and latency; inclinometer outputs are not kept."""

    gyro: tuple[int, int, int]
    accel: tuple[int, int, int]
    gyro_status: int = 0
    accel_status: int = 0
    incl_status: int = 0
    gyro_temp: tuple[int, int, int] = (0, 0, 0)
    accel_temp: tuple[int, int, int] = (0, 0, 0)
    counter: int = 0
    latency_us: int = 0


class Stim300Options(Model):
    """The STIM300's own configuration (its service-mode settings)."""

    datagram: Literal[0x91, 0x93, 0xA5, 0xA7] = 0x91
    gyro_output: Literal["rate", "increment"] = "increment"  # angular rate (or average) deg/s; incremental deg
    accel_output: Literal["acceleration", "increment"] = "increment"  # (average) acceleration g; incremental m/s
    accel_range_g: Literal[5, 10, 30, 80] = 10


def layout(datagram: int) -> dict[str, int]:
    """Byte offsets of a datagram's parts: gyro, accel, inclinometer status, temperatures, counter; its length."""
    incl, temp, _ = DATAGRAMS[datagram]
    at = 21 + 10 * incl  # after the identifier, the gyros and the accelerometers (each 9 + status)
    out = {"gyro": 1, "accel": 11, "incl_status": 30 if incl else -1, "gyro_temp": at if temp else -1,
           "accel_temp": at + 7 if temp else -1}
    at += 7 * (2 + incl) * temp
    return out | {"counter": at, "length": at + 3 + 4}


def _int24(rows: np.ndarray, at: int) -> np.ndarray:
    """The three 24-bit two's-complement values at byte ``at`` of each row, as int32 (N, 3)."""
    b = rows[:, at:at + 9].astype(np.int32).reshape(-1, 3, 3)
    v = (b[:, :, 0] << 16) | (b[:, :, 1] << 8) | b[:, :, 2]
    return v - ((v & 0x800000) << 1)


def _int16(rows: np.ndarray, at: int) -> np.ndarray:
    b = rows[:, at:at + 6].astype(np.int32).reshape(-1, 3, 2)
    v = (b[:, :, 0] << 8) | b[:, :, 1]
    return v - ((v & 0x8000) << 1)


class Stim300Codec(ByteCodec[StimDatagram]):
    """Encode and decode the configured normal-mode datagram; increments in SI at ``rate_hz``, which must be
    one of the device's sample rates (2000 / 2^k Hz): its counter steps by ``2000 / rate_hz`` a datagram."""

    name: ClassVar[str] = "stim300"
    kind: ClassVar[str] = Stream.IMU
    header_size: ClassVar[int] = 1
    Options: ClassVar[type[Model]] = Stim300Options
    health_flags: ClassVar[tuple[HealthFlag, ...]] = HEALTH_FLAGS
    start_up_flags: ClassVar[tuple[str, ...]] = ("gyro_start_up", "accel_start_up")  # about 0.5 s after power-on
    unit_keys: ClassVar[tuple[str, str, str]] = ("imu.options.accel_output and imu.options.accel_range_g",
                                                 "imu.options.gyro_output", "imu.options.gyro_output")

    def __init__(self, rate_hz: float, **options: Any) -> None:
        super().__init__(rate_hz, **options)
        o = self.options
        step = INTERNAL_HZ / rate_hz
        if step != int(step) or 256 % int(step):
            raise ValueError(f"stim300: rate_hz {rate_hz:g} is not a sample rate of the device (2000, 1000, 500, "
                             "250 or 125 Hz): its counter of 2000 internal samples/s could not be followed")
        self.step = int(step)
        self.sequence_modulus = 256 // self.step
        self.sync = bytes([o.datagram])
        self.at = layout(o.datagram)
        self.dummy = DATAGRAMS[o.datagram][2]
        dt = 1.0 / rate_hz
        deg = math.pi / 180.0
        # counts -> rad and m/s over one sample interval
        self.gyro_scale = GYRO_LSB[o.gyro_output] * deg * (dt if o.gyro_output == "rate" else 1.0)
        bits = ACCEL_FRACTION[o.accel_range_g][o.accel_output == "increment"]
        self.accel_scale = 2.0 ** -bits * (G0 * dt if o.accel_output == "acceleration" else 1.0)

    def frame_lengths(self, buf: np.ndarray, starts: np.ndarray) -> np.ndarray:
        return np.full(len(starts), self.at["length"], dtype=np.int64)

    def parse(self, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.at["length"]
        rows = fixed_rows(buf, starts, n)
        padded = np.concatenate((rows[:, :n - 4], np.zeros((len(rows), self.dummy), dtype=np.uint8)), axis=1)
        crc = (rows[:, n - 4:].astype(np.uint32) << np.array([24, 16, 8, 0], dtype=np.uint32)).sum(axis=1)
        valid = crc_rows(crc32_mpeg2, padded) == crc
        rows, at = rows[valid], self.at
        out = np.zeros(len(rows), dtype=FIELDS)
        out["gyro"], out["accel"] = _int24(rows, at["gyro"]), _int24(rows, at["accel"])
        out["gyro_status"], out["accel_status"] = rows[:, 10], rows[:, 20]
        if at["incl_status"] >= 0:
            out["incl_status"] = rows[:, at["incl_status"]]
        if at["gyro_temp"] >= 0:
            out["gyro_temp"], out["accel_temp"] = _int16(rows, at["gyro_temp"]), _int16(rows, at["accel_temp"])
        c = at["counter"]
        out["counter"] = rows[:, c]
        out["latency_us"] = (rows[:, c + 1].astype(np.uint16) << 8) | rows[:, c + 2]
        return valid, out

    def record(self, row: Any) -> StimDatagram:
        return StimDatagram(tuple(row["gyro"].tolist()), tuple(row["accel"].tolist()), int(row["gyro_status"]),
                            int(row["accel_status"]), int(row["incl_status"]), tuple(row["gyro_temp"].tolist()),
                            tuple(row["accel_temp"].tolist()), int(row["counter"]), int(row["latency_us"]))

    def encode(self, record: StimDatagram) -> bytes:
        """The datagram; its inclinometer outputs (when the datagram has them) are sent as zero."""
        incl, temp, _ = DATAGRAMS[self.options.datagram]
        out = bytearray(self.sync)
        for values, status in ((record.gyro, record.gyro_status), (record.accel, record.accel_status)) + (
                ((0, 0, 0), record.incl_status),) * incl:
            out += b"".join((v & 0xFFFFFF).to_bytes(3, "big") for v in values) + bytes([status])
        if temp:
            for values in (record.gyro_temp, record.accel_temp) + ((0, 0, 0),) * incl:
                out += b"".join((v & 0xFFFF).to_bytes(2, "big") for v in values) + b"\x00"
        out += bytes([record.counter & 0xFF]) + record.latency_us.to_bytes(2, "big")
        return bytes(out) + crc32_mpeg2(bytes(out) + bytes(self.dummy)).to_bytes(4, "big")

    def sequences(self, rows: np.ndarray) -> np.ndarray:
        """The datagram count the 2000/s counter implies (the counter over its step, modulo 256 / step)."""
        return rows["counter"].astype(np.int64) // self.step

    def status_words(self, rows: np.ndarray) -> np.ndarray:
        """The gyros', accelerometers' and inclinometers' status bytes, from the low byte up."""
        return (rows["gyro_status"].astype(np.int64) | (rows["accel_status"].astype(np.int64) << 8)
                | (rows["incl_status"].astype(np.int64) << 16))

    def samples(self, frames: FrameBatch) -> ImuSamples:
        """The increments; the temperature the mean of the gyros' and accelerometers' six (NaN in a datagram
        without temperatures)."""
        rows = frames.rows
        temperature = (np.concatenate((rows["gyro_temp"], rows["accel_temp"]), axis=1).mean(axis=1) / TEMP_LSB
                       if DATAGRAMS[self.options.datagram][1] else np.full(len(rows), np.nan))
        return ImuSamples(frames.sync_index, rows["gyro"] * self.gyro_scale, rows["accel"] * self.accel_scale,
                          np.full(len(frames), frames.host_time), self.status_words(rows), temperature)

    def from_sample(self, sample: ImuSample) -> StimDatagram:
        """The datagram of an SI sample (outputs rounded to the nearest count; its status, its temperature in every
        temperature field of a datagram that has them, 0 us latency)."""
        limit = 1 << 23
        status = self.sent_status(sample)

        def counts(values: Vec3, scale: float) -> tuple[int, int, int]:
            raw = tuple(round(v / scale) for v in values)
            if any(not -limit <= r < limit for r in raw):
                raise ValueError(f"stim300: {values} is outside the 24-bit output range")
            return raw

        temp = (0 if math.isnan(sample.temperature_c) else round(sample.temperature_c * TEMP_LSB),) * 3
        return StimDatagram(counts(sample.dtheta, self.gyro_scale), counts(sample.dv, self.accel_scale),
                            status & 0xFF, (status >> 8) & 0xFF, (status >> 16) & 0xFF, temp, temp,
                            counter=(sample.sync_index * self.step) & 0xFF)

    def csv_header(self) -> list[str]:
        o = self.options
        gyro = "deg_s" if o.gyro_output == "rate" else "deg"
        accel = "g" if o.accel_output == "acceleration" else "mps"
        return ([f"gyro_{c}_{gyro}" for c in "xyz"] + [f"accel_{c}_{accel}" for c in "xyz"]
                + ["gyro_status", "accel_status", "incl_status"] + [f"gyro_temp_{c}_c" for c in "xyz"]
                + [f"accel_temp_{c}_c" for c in "xyz"] + ["counter", "latency_us"])

    def csv_row(self, record: StimDatagram) -> list[Any]:
        o = self.options
        bits = ACCEL_FRACTION[o.accel_range_g][o.accel_output == "increment"]
        return ([v * GYRO_LSB[o.gyro_output] for v in record.gyro] + [v * 2.0 ** -bits for v in record.accel]
                + [f"0x{s:02X}" for s in (record.gyro_status, record.accel_status, record.incl_status)]
                + [t / TEMP_LSB for t in record.gyro_temp + record.accel_temp] + [record.counter, record.latency_us])
