"""Codecs against golden byte vectors written by hand from the protocol text (docs/wire-formats.md)."""

from __future__ import annotations

import math

import pytest
from crccheck.crc import Crc16Xmodem, Crc32Mpeg2
from hypothesis import given
from hypothesis import strategies as st

from drivers.codec import DecodeError
from drivers.crc import crc16_xmodem, crc32_mpeg2
from drivers.kvh1750 import STATUS_ALL_VALID, Kvh1750Codec, KvhFrame
from drivers.registry import CODECS, imu_codec, make_codec
from drivers.tts1 import Tts1Codec, Tts1Frame, wrap_udeg
from drivers.xsens import XsensCodec
from hil.config import parse_config
from hil.samples import ImuSample, TableSample

KVH_PUBLISHED = bytes.fromhex("FE81FF55 37A96A6E 38586C1F B75BF862 BF803E78 BB650D28 3B0A37AC 77 3D 0028 4BFA34D8")


def test_crc_check_values_match_the_catalogue():
    assert crc32_mpeg2(b"123456789") == 0x0376E6E7
    assert crc16_xmodem(b"123456789") == 0x31C3


@given(st.binary(max_size=300))
def test_crcs_agree_with_crccheck(data):
    assert crc32_mpeg2(data) == Crc32Mpeg2.calc(data)
    assert crc16_xmodem(data) == Crc16Xmodem.calc(data)


def test_kvh_published_vector_decodes_to_the_published_values():
    assert Crc32Mpeg2.calc(KVH_PUBLISHED[:32]) == 0x4BFA34D8
    frame = Kvh1750Codec(rate_hz=1000).decode(KVH_PUBLISHED)
    assert frame.gyro == pytest.approx((2.0195930e-05, 5.1599109e-05, -1.3111248e-05), rel=1e-7)
    assert frame.accel == pytest.approx((-1.0019064, -0.0034950469, 0.0021090312), rel=1e-7)
    assert (frame.status, frame.sequence, frame.temperature) == (0x77, 61, 40)


def test_kvh_encoder_reproduces_the_published_vector():
    codec = Kvh1750Codec(rate_hz=1000)
    assert codec.encode(codec.decode(KVH_PUBLISHED)) == KVH_PUBLISHED


def test_kvh_hand_written_frame_with_negative_temperature():
    body = bytes.fromhex("FE81FF55 3F800000 C0000000 3F000000 00000000 00000000 3F800000 77 7F FFFB")
    frame = body + Crc32Mpeg2.calc(body).to_bytes(4, "big")
    record = Kvh1750Codec(rate_hz=1000).decode(frame)
    assert record == KvhFrame((1.0, -2.0, 0.5), (0.0, 0.0, 1.0), 0x77, 127, -5)


def test_kvh_rejects_a_flipped_bit():
    damaged = bytearray(KVH_PUBLISHED)
    damaged[10] ^= 0x04
    with pytest.raises(DecodeError, match="CRC"):
        Kvh1750Codec(rate_hz=1000).decode(bytes(damaged))


def test_kvh_rate_output_in_degrees_becomes_increments_in_radians():
    codec = Kvh1750Codec(rate_hz=200, gyro_unit="deg", gyro_output="rate", accel_unit="g")
    record = KvhFrame((10.0, 0.0, -20.0), (0.0, 0.0, 1.0), 0x77, 3, 25)
    samples = codec.samples(codec.framer().feed_bytes(codec.encode(record), 1.5))
    assert samples.dtheta[0] == pytest.approx((math.radians(10) / 200, 0.0, -math.radians(20) / 200))
    assert samples.dv[0] == pytest.approx((0.0, 0.0, 9.80665 / 200))
    assert (samples.sync_index[0], samples.host_time[0], samples.status[0]) == (3, 1.5, 0x77)


def test_kvh_from_sample_round_trips_through_the_wire():
    codec = Kvh1750Codec(rate_hz=1000)
    sample = ImuSample(300, (1e-5, -2e-5, 3e-6), (1e-3, 2e-3, -9.8e-3), status=STATUS_ALL_VALID)
    frames = codec.framer().feed_bytes(codec.encode(codec.from_sample(sample)))
    assert codec.record(frames.rows[0]).sequence == 300 % 128 and codec.record(frames.rows[0]).temperature == 25
    back = codec.samples(frames)
    assert back.dtheta[0] == pytest.approx(sample.dtheta, rel=1e-7)
    assert back.dv[0] == pytest.approx(sample.dv, rel=1e-7)


TTS1_BODY = bytes.fromhex("5453 01 21 E8030000 804A5D05 A0B949FD FF94BA0A 3200")


def test_tts1_hand_written_frame():
    frame = TTS1_BODY + Crc16Xmodem.calc(TTS1_BODY[2:]).to_bytes(2, "big")
    record = Tts1Codec().decode(frame)
    assert record == Tts1Frame(0x21, 1000, (90_000_000, -45_500_000, 179_999_999), 50)
    sample = Tts1Codec().samples(Tts1Codec().framer().feed_bytes(frame, 2.0))
    assert sample.angles[0] == pytest.approx((math.pi / 2, math.radians(-45.5), math.radians(179.999999)))
    assert sample.latch_delay[0] == pytest.approx(50e-6)
    assert Tts1Codec().encode(record) == frame


def test_tts1_crc_is_big_endian_over_bytes_2_to_21():
    frame = bytearray(TTS1_BODY + Crc16Xmodem.calc(TTS1_BODY[2:]).to_bytes(2, "big"))
    frame[22], frame[23] = frame[23], frame[22]
    with pytest.raises(DecodeError):
        Tts1Codec().decode(bytes(frame))


def test_tts1_angles_wrap_to_minus_180_inclusive():
    assert wrap_udeg(180e6) == -180_000_000
    assert wrap_udeg(-180e6) == -180_000_000
    assert wrap_udeg(540e6 + 1) == -179_999_999
    codec = Tts1Codec()
    frame = codec.encode(codec.from_sample(TableSample(1, (math.pi, 0.0, -math.pi))))
    assert frame[8:12] == bytes.fromhex("006B45F5")
    assert codec.decode(frame).angles_udeg == (-180_000_000, 0, -180_000_000)


XSENS = bytes.fromhex(
    "FA FF 36 2E"
    "1020 02 012C"  # PacketCounter 300
    "1060 04 000186A0"  # SampleTimeFine 100000 (10 s)
    "8030 10 3F800000 00000000 00000000 00000000"  # DeltaQ identity
    "4010 0C 3F000000 BE800000 40000000"  # DeltaV (0.5, -0.25, 2.0)
    "0B")


def test_xsens_hand_written_message():
    assert sum(XSENS[1:]) % 256 == 0
    codec = XsensCodec(rate_hz=100)
    record = codec.decode(XSENS)
    assert (record.packet_counter, record.sample_time_fine) == (300, 100000)
    assert record.delta_q == (1.0, 0.0, 0.0, 0.0) and record.delta_v == (0.5, -0.25, 2.0)
    samples = codec.samples(codec.framer().feed_bytes(XSENS))
    assert samples.dtheta.tolist() == [[0.0, 0.0, 0.0]] and samples.sync_index.tolist() == [300]
    assert codec.encode(record) == XSENS


def test_xsens_extended_length_and_unknown_items_are_handled():
    payload = bytes.fromhex("ABCD FA") + bytes(250) + bytes.fromhex(
        "1020 02 0007 8020 0C 3F800000 00000000 00000000 4020 0C 00000000 00000000 3F800000")
    header = bytes.fromhex("FAFF36FF") + len(payload).to_bytes(2, "big")
    message = header + payload + bytes([-sum(header[1:] + payload) & 0xFF])
    codec = XsensCodec(rate_hz=50)
    record = codec.decode(message)
    assert record.packet_counter == 7 and record.rate_of_turn == (1.0, 0.0, 0.0)
    samples = codec.samples(codec.framer().feed_bytes(message))
    assert samples.dtheta[0] == pytest.approx((1 / 50, 0.0, 0.0)) and samples.dv[0] == pytest.approx((0.0, 0.0, 1 / 50))


def test_xsens_rejects_a_bad_checksum_and_a_bad_item_size():
    codec = XsensCodec(rate_hz=100)
    with pytest.raises(DecodeError, match="checksum"):
        codec.decode(XSENS[:-1] + b"\x0c")
    bad = bytearray(XSENS)
    bad[6] = 0x03  # PacketCounter announced as 3 bytes
    bad[-1] = (bad[-1] - 1) & 0xFF
    with pytest.raises(DecodeError):
        codec.decode(bytes(bad))


@given(st.tuples(*[st.floats(-0.5, 0.5)] * 3), st.tuples(*[st.floats(-10, 10)] * 3),
       st.integers(0, 10**6), st.sampled_from(["increments", "rates"]))
def test_xsens_from_sample_round_trips(dtheta, dv, index, outputs):
    codec = XsensCodec(rate_hz=400, outputs=outputs)
    sample = ImuSample(index, dtheta, dv, device_time=index / 400)
    back = codec.samples(codec.framer().feed_bytes(codec.encode(codec.from_sample(sample))))
    assert back.sync_index.tolist() == [index % 65536]
    assert back.dtheta[0] == pytest.approx(dtheta, rel=1e-6, abs=1e-7)
    assert back.dv[0] == pytest.approx(dv, rel=1e-6, abs=1e-6)


def test_registry_finds_every_protocol_by_name():
    for name in ("kvh1750", "xsens-mtdata2", "can-dbc", "tts1", "acl"):
        assert CODECS.get(name).name == name
    assert make_codec("kvh1750", rate_hz=100).rate_hz == 100
    with pytest.raises(ValueError, match="'nmea': unknown; protocols: acl, can-dbc, kvh1750, stim300, tts1, xsens"):
        CODECS.get("nmea")


def test_imu_codec_follows_the_config():
    base = {"trial": {"duration_s": 10}, "site": {"latitude_deg": 32}}
    kvh = imu_codec(parse_config({**base, "imu": {"options": {"gyro_unit": "deg", "gyro_output": "rate"}}}).imu, 400)
    assert (kvh.name, kvh.gyro_unit, kvh.gyro_output, kvh.rate_hz) == ("kvh1750", "deg", "rate", 400)
    can_cfg = parse_config({**base, "imu": {"source": "can", "protocol": "can-dbc", "can": {}}}).imu
    assert imu_codec(can_cfg, 200).sync_modulus == 1 << 24
