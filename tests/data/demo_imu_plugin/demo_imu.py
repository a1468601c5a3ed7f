"""A made-up IMU protocol, as a third party would add one: ``DM`` counter(u16) dtheta(3 x i32, LSB rad)
dv(3 x i32, LSB m/s) status(u8) xor(u8), big-endian; the LSBs are the device's settings (``imu.options``)."""

from typing import Any, ClassVar

import numpy as np

from drivers.codec import FrameBatch
from drivers.framing import ByteCodec, fixed_rows
from hil.config_types import Model
from hil.samples import ImuSample, ImuSamples

SIZE = 30
FIELDS = np.dtype([("sync", "S2"), ("counter", ">u2"), ("dtheta", ">i4", 3), ("dv", ">i4", 3), ("status", "u1"),
                   ("xor", "u1")])


class DemoOptions(Model):
    dtheta_lsb_rad: float = 1e-9
    dv_lsb_mps: float = 1e-8


class DemoCodec(ByteCodec[tuple]):
    name: ClassVar[str] = "demo-imu"
    kind: ClassVar[str] = "imu"
    sync: ClassVar[bytes] = b"DM"
    header_size: ClassVar[int] = 2
    sequence_modulus: ClassVar[int] = 1 << 16
    Options: ClassVar[type[Model]] = DemoOptions

    def frame_lengths(self, buf, starts):
        return np.full(len(starts), SIZE, dtype=np.int64)

    def parse(self, buf, starts, lengths):
        frames = fixed_rows(buf, starts, SIZE)
        valid = np.bitwise_xor.reduce(frames, axis=1) == 0
        return valid, frames[valid].view(FIELDS)[:, 0]

    def record(self, row: Any) -> tuple:
        return int(row["counter"]), tuple(row["dtheta"].tolist()), tuple(row["dv"].tolist()), int(row["status"])

    def encode(self, record: tuple) -> bytes:
        counter, dtheta, dv, status = record
        body = b"DM" + counter.to_bytes(2, "big") + b"".join(v.to_bytes(4, "big", signed=True) for v in dtheta + dv)
        body += bytes([status])
        xor = 0
        for b in body:
            xor ^= b
        return body + bytes([xor])

    def sequences(self, rows):
        return rows["counter"].astype(np.int64)

    def samples(self, frames: FrameBatch) -> ImuSamples:
        o = self.options
        return ImuSamples(frames.sync_index, frames.rows["dtheta"] * o.dtheta_lsb_rad, frames.rows["dv"] * o.dv_lsb_mps,
                          np.full(len(frames), frames.host_time), frames.rows["status"].astype(np.int64))

    def from_sample(self, sample: ImuSample) -> tuple:
        o = self.options
        return (sample.sync_index & 0xFFFF, tuple(round(v / o.dtheta_lsb_rad) for v in sample.dtheta),
                tuple(round(v / o.dv_lsb_mps) for v in sample.dv), sample.status & 0xFF)

    def csv_header(self) -> list[str]:
        return ["counter", "dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z", "status"]

    def csv_row(self, record: tuple) -> list[Any]:
        return [record[0], *record[1], *record[2], record[3]]
