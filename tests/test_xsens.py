"""Xsens MTData2 as devices send it: every precision of DeltaQ, DeltaV, Acceleration and RateOfTurn, the
status items, other items skipped and counted; golden messages written by hand from the MTData2
specification, and real captures with the values another decoder gave for them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from drivers.xsens import MtData2Frame, XsensCodec

CAPTURES = Path(__file__).parent / "data" / "xsens_captures"

# PacketCounter 300, StatusByte 0x05, then DeltaQ (1, 0, 0, 0), DeltaV, Acceleration (1, -0.25, 0.5),
# RateOfTurn (0.5, 0, -0.25) at the precision the identifier's low bits give, and an EulerAngles item
# (0x2030, Float32) that is not read. Float32: IEEE single; FP12.20: int32 of value * 2^20; FP16.32:
# the 32-bit fraction, then the signed 16-bit integer part of value * 2^32; Float64: IEEE double.
GOLDEN = {
    "float32": ("FA FF 36 58  1020 02 012C  E010 01 05"
                " 8030 10 3F800000 00000000 00000000 00000000"
                " 4010 0C 3F000000 BE800000 40000000"  # DeltaV (0.5, -0.25, 2)
                " 4020 0C 3F800000 BE800000 3F000000"
                " 8020 0C 3F000000 00000000 BE800000"
                " 2030 0C 3F800000 3F800000 3F800000  1C", (0.5, -0.25, 2.0)),
    "fp12.20": ("FA FF 36 58  1020 02 012C  E010 01 05"
                " 8031 10 00100000 00000000 00000000 00000000"
                " 4011 0C 00080000 FFFC0000 00200000"
                " 4021 0C 00100000 FFFC0000 00080000"
                " 8021 0C 00080000 00000000 FFFC0000"
                " 2030 0C 3F800000 3F800000 3F800000  04", (0.5, -0.25, 2.0)),
    "fp16.32": ("FA FF 36 72  1020 02 012C  E010 01 05"
                " 8032 18 00000000 0001 00000000 0000 00000000 0000 00000000 0000"
                " 4012 12 80000000 0000 C0000000 FFFF 00000000 0002"
                " 4022 12 00000000 0001 C0000000 FFFF 80000000 0000"
                " 8022 12 80000000 0000 00000000 0000 C0000000 FFFF"
                " 2030 0C 3F800000 3F800000 3F800000  57", (0.5, -0.25, 2.0)),
    "float64": ("FA FF 36 8C  1020 02 012C  E010 01 05"
                " 8033 20 3FF0000000000000 0000000000000000 0000000000000000 0000000000000000"
                " 4013 18 3FB999999999999A BFD0000000000000 4000000000000000"  # DeltaV (0.1, -0.25, 2)
                " 4023 18 3FF0000000000000 BFD0000000000000 3FE0000000000000"
                " 8023 18 3FE0000000000000 0000000000000000 BFD0000000000000"
                " 2030 0C 3F800000 3F800000 3F800000  C5", (0.1, -0.25, 2.0)),
}


@pytest.mark.parametrize("precision", list(GOLDEN))
def test_every_precision_decodes_to_the_values_the_specification_gives(precision):
    message, delta_v = bytes.fromhex(GOLDEN[precision][0]), GOLDEN[precision][1]
    assert sum(message[1:]) % 256 == 0
    codec = XsensCodec(rate_hz=100)
    framer = codec.framer()
    frames = framer.feed_bytes(message)
    record = codec.record(frames.rows[0])
    assert record == MtData2Frame(packet_counter=300, status_byte=5, delta_q=(1.0, 0.0, 0.0, 0.0), delta_v=delta_v,
                                  acceleration=(1.0, -0.25, 0.5), rate_of_turn=(0.5, 0.0, -0.25))
    samples = codec.samples(frames)
    assert samples.dtheta.tolist() == [[0.0, 0.0, 0.0]] and samples.dv.tolist() == [list(delta_v)]
    assert samples.status.tolist() == [5]
    assert framer.counters.as_dict() == {"frames": 1, "corrupt": 0, "skipped_bytes": 0, "gaps": 0,
                                         "skipped_items": {"EulerAngles 0x2030": 1}}


@pytest.mark.parametrize("precision", list(GOLDEN))
def test_the_encoder_writes_the_hand_written_items(precision):
    message, delta_v = bytes.fromhex(GOLDEN[precision][0]), GOLDEN[precision][1]
    record = MtData2Frame(packet_counter=300, status_byte=5, delta_q=(1.0, 0.0, 0.0, 0.0), delta_v=delta_v,
                          acceleration=(1.0, -0.25, 0.5), rate_of_turn=(0.5, 0.0, -0.25))
    payload = message[4:-16]  # without the EulerAngles item
    expected = bytes([0xFA, 0xFF, 0x36, len(payload)]) + payload
    expected += bytes([-sum(expected[1:]) & 0xFF])
    assert XsensCodec(100, precision=precision).encode(record) == expected


def test_fixed_point_keeps_what_float32_cannot():
    """FP16.32 resolves 2^-32: 1 + 2^-32 and -2^-32 come through exactly."""
    codec = XsensCodec(100, precision="fp16.32")
    frame = codec.encode(MtData2Frame(packet_counter=1, delta_v=(1.0 + 2.0 ** -32, -(2.0 ** -32), -32768.0)))
    assert codec.decode(frame).delta_v == (1.0 + 2.0 ** -32, -(2.0 ** -32), -32768.0)
    with pytest.raises(ValueError, match="FP16.32"):
        codec.encode(MtData2Frame(delta_v=(32768.0, 0.0, 0.0)))


def test_rates_without_increments_are_integrated_over_one_sample():
    codec = XsensCodec(200, precision="fp12.20", outputs="rates")
    frames = codec.framer().feed_bytes(codec.encode(MtData2Frame(packet_counter=7, acceleration=(0.0, 0.0, 9.75),
                                                                 rate_of_turn=(0.5, -0.25, 0.0))))
    samples = codec.samples(frames)
    assert samples.dtheta.tolist() == [[0.5 / 200, -0.25 / 200, 0.0]]
    assert samples.dv.tolist() == [[0.0, 0.0, 9.75 / 200]]


def test_an_item_of_the_wrong_size_for_its_precision_is_corrupt():
    message = bytearray.fromhex(GOLDEN["fp16.32"][0])
    message[14] = 0x31  # DeltaQ announced as FP12.20 with 6-byte numbers
    message[-1] = -sum(message[1:-1]) & 0xFF
    framer = XsensCodec(100).framer()
    assert len(framer.feed_bytes(bytes(message))) == 0 and framer.counters.corrupt == 1


def _rotation_vector(q: list[float]) -> np.ndarray:
    """The rotation vector of a unit quaternion, by the half angle's sine and cosine (the capture's quaternions are
    unit to the precision of their numbers, 1.2e-7 for Float32)."""
    half = math.atan2(math.sqrt(q[1] ** 2 + q[2] ** 2 + q[3] ** 2), q[0])
    s = math.sin(half)
    return np.zeros(3) if s == 0 else 2 * half / s * np.array(q[1:])


@pytest.mark.parametrize("precision", ["float32", "fp12.20", "fp16.32", "float64"])
def test_real_captures_decode_to_the_published_values(precision):
    expected = json.loads((CAPTURES / "decoded.json").read_text())[precision]
    codec = XsensCodec(rate_hz=100)
    framer = codec.framer()
    frames = framer.feed_bytes((CAPTURES / f"{precision}.bin").read_bytes())
    assert framer.counters.frames == len(expected) and framer.counters.corrupt == 0
    assert framer.counters.skipped_bytes == 0 and "UtcTime 0x1010" in framer.counters.skipped_items
    samples = codec.samples(frames)
    with_increments = [m for m in expected if "delta_q" in m]
    assert len(samples) == len(with_increments) > 0
    for k, want in enumerate(expected):
        record = codec.record(frames.rows[k])
        assert record.packet_counter == want["packet_counter"]
        assert record.sample_time_fine == want["sample_time_fine"]
        assert (record.status_byte, record.status_word) == (want.get("status_byte"), want.get("status_word"))
        for name in ("delta_q", "delta_v", "acceleration", "rate_of_turn"):
            got = getattr(record, name)
            assert (got is None) == (name not in want)
            if got is not None:
                assert got == pytest.approx(want[name], rel=1e-12, abs=0)
    for k, want in enumerate(with_increments):
        assert samples.dtheta[k] == pytest.approx(_rotation_vector(want["delta_q"]), rel=1e-6, abs=1e-13)
        assert samples.dv[k].tolist() == pytest.approx(want["delta_v"], rel=1e-12)


def test_a_sensor_item_in_another_coordinate_setting_is_skipped_and_counted():
    """Bits 2-3 of an identifier select the coordinate system; a DeltaV sent with them set (0x4014, NED) is
    not read as the sensor-frame DeltaV, and no sample comes of the message."""
    message = bytes.fromhex("FA FF 36 14  1020 02 0001  4014 0C 3F000000 00000000 00000000")
    message += bytes([-sum(message[1:]) & 0xFF])
    codec = XsensCodec(100)
    framer = codec.framer()
    frames = framer.feed_bytes(message)
    assert codec.record(frames.rows[0]).delta_v is None and len(codec.samples(frames)) == 0
    assert framer.counters.skipped_items == {"DeltaV 0x4014": 1}
