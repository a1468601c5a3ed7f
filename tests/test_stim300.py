"""STIM300 normal-mode datagrams against golden bytes written by hand from the datasheet TS1524: the outputs
and their scaling (7.5.2.2), status bytes (5.6), counter and latency, the CRC-32 with its dummy bytes (5.5.7)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from crccheck.crc import Crc32Mpeg2

from drivers.stim300 import DATAGRAMS, Stim300Codec, StimDatagram, layout
from hil.samples import ImuSample
from hil.units import G0

# 0x91 (rate and acceleration): gyro 1, -1, 0.5 deg/s (2^14 counts per deg/s), status OK; accelerometers
# (10 g range) 1, -0.5, 0 g (2^19 counts per g); counter 16; latency 0x0204 = 516 us; CRC over the
# 24 bytes (a whole number of words: no dummy byte).
RATE_91 = bytes.fromhex("91 004000 FFC000 002000 00  080000 FC0000 000000 00  10 0204  B50DF3D4")
# 0x93 (rate, acceleration, inclination) as increments: gyro 0.5 deg, -2^-21 deg, 0 (2^21 per deg);
# accelerometers (10 g range) 0.25, -1, 2^-22 m/s (2^22 per m/s); inclinometers zero; counter 254;
# CRC over the 34 bytes and 2 dummy zero bytes (Table 5-22).
INCREMENT_93 = bytes.fromhex("93 100000 FFFFFF 000000 00  100000 C00000 000001 00  000000 000000 000000 00"
                             "  FE 0000  9F8CBCD2")
# 0xA5 (rate, acceleration, temperature): gyro status 0x40 (start-up), gyro temperatures 25.5, -1, 0 deg C
# (1/256 deg C per count), accelerometer temperatures 25 deg C; counter 2; CRC with 2 dummy bytes.
TEMPERATURE_A5 = bytes.fromhex("A5 004000 FFC000 002000 40  080000 FC0000 000000 00  1980 FF00 0000 00"
                               "  1900 1900 1900 00  02 0204  23341CAD")


def test_the_crc_is_the_datasheets_over_the_datagram_and_its_dummy_bytes():
    for golden, dummy in ((RATE_91, 0), (INCREMENT_93, 2), (TEMPERATURE_A5, 2)):
        assert DATAGRAMS[golden[0]][2] == dummy == -(len(golden) - 4) % 4
        assert Crc32Mpeg2.calc(golden[:-4] + bytes(dummy)) == int.from_bytes(golden[-4:], "big")
    assert [layout(d)["length"] - 4 for d in (0x91, 0x93, 0xA5, 0xA7)] == [24, 34, 38, 55]  # 0xA7: 55 (5.5.7)


def test_rate_and_acceleration_become_increments_over_one_sample():
    codec = Stim300Codec(500, datagram=0x91, gyro_output="rate", accel_output="acceleration", accel_range_g=10)
    assert codec.decode(RATE_91) == StimDatagram((1 << 14, -(1 << 14), 1 << 13), (1 << 19, -(1 << 18), 0),
                                                 counter=16, latency_us=516)
    samples = codec.samples(codec.framer().feed_bytes(RATE_91))
    deg = math.pi / 180
    assert samples.dtheta[0] == pytest.approx(np.array([1.0, -1.0, 0.5]) * deg / 500, rel=1e-15)
    assert samples.dv[0] == pytest.approx(np.array([1.0, -0.5, 0.0]) * G0 / 500, rel=1e-15)
    assert samples.sync_index.tolist() == [16 // 4]  # 2000 internal samples/s: the counter steps by 4 at 500 Hz
    assert codec.encode(codec.decode(RATE_91)) == RATE_91


def test_incremental_outputs_with_inclinometers_and_dummy_bytes():
    codec = Stim300Codec(2000, datagram=0x93, gyro_output="increment", accel_output="increment", accel_range_g=10)
    record = codec.decode(INCREMENT_93)
    assert record.gyro == (1 << 20, -1, 0) and record.accel == (1 << 20, -(1 << 22), 1) and record.counter == 254
    samples = codec.samples(codec.framer().feed_bytes(INCREMENT_93))
    assert samples.dtheta[0] == pytest.approx((0.5 * math.pi / 180, -2.0 ** -21 * math.pi / 180, 0.0), rel=1e-15)
    assert samples.dv[0].tolist() == [0.25, -1.0, 2.0 ** -22]
    assert codec.encode(record) == INCREMENT_93


def test_status_bytes_and_temperatures():
    codec = Stim300Codec(1000, datagram=0xA5, gyro_output="rate", accel_output="acceleration")
    record = codec.decode(TEMPERATURE_A5)
    assert (record.gyro_status, record.accel_status) == (0x40, 0x00)
    assert record.gyro_temp == (6528, -256, 0) and record.accel_temp == (6400,) * 3
    assert codec.csv_row(record)[9:15] == [25.5, -1.0, 0.0, 25.0, 25.0, 25.0]
    samples = codec.samples(codec.framer().feed_bytes(TEMPERATURE_A5))
    assert samples.status.tolist() == [0x40] and samples.sync_index.tolist() == [1]
    assert codec.encode(record) == TEMPERATURE_A5


def test_a_damaged_datagram_is_corrupt_and_the_next_is_read():
    codec = Stim300Codec(500, datagram=0x91, gyro_output="rate", accel_output="acceleration")
    damaged = bytearray(RATE_91)
    damaged[5] ^= 0x01
    framer = codec.framer()
    frames = framer.feed_bytes(bytes(damaged) + RATE_91)
    assert len(frames) == 1 and framer.counters.corrupt == 1


def test_the_counter_of_internal_samples_is_followed_across_its_wrap():
    codec = Stim300Codec(250)  # the counter steps by 8: 32 datagrams a wrap
    samples = [ImuSample(k, (1e-5, 0.0, -1e-5), (0.0, 0.0, 0.04)) for k in range(20, 100)]
    frames = codec.framer().feed_bytes(b"".join(codec.encode(codec.from_sample(s)) for s in samples))
    assert frames.rows["counter"][:3].tolist() == [(8 * k) % 256 for k in (20, 21, 22)]
    assert frames.sync_index.tolist() == list(range(20, 100))
    back = codec.samples(frames)
    assert back.dtheta == pytest.approx(np.array([s.dtheta for s in samples]), abs=0.5 * codec.gyro_scale)
    assert back.dv == pytest.approx(np.array([s.dv for s in samples]), abs=0.5 * codec.accel_scale)


def test_a_rate_the_counter_cannot_follow_is_refused():
    with pytest.raises(ValueError, match="not a sample rate of the device"):
        Stim300Codec(200)


def test_hil_decode_reads_a_capture_with_the_devices_settings(tmp_path, capsys):
    from hil.cli import main

    (tmp_path / "cap.bin").write_bytes(b"\x00\x93" + INCREMENT_93)  # a false identifier before the datagram
    args = ["decode", "stim300", str(tmp_path / "cap.bin"), "--rate", "2000", "--option", "datagram=0x93"]
    assert main([*args, "--option", "gyro_output=increment", "--out", str(tmp_path / "out.csv")]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1] == (
        '{"frames": 1, "corrupt": 1, "skipped_bytes": 2, "gaps": 0, "invalid": 0}')
    rows = (tmp_path / "out.csv").read_text().splitlines()
    assert rows[1].split(",")[1:3] == ["0.5", f"{-2.0 ** -21}"]
    assert main(["decode", "stim300", str(tmp_path / "cap.bin"), "--option", "datagram=0x93"]) == 2
    assert "rate_hz 200 is not a sample rate of the device" in capsys.readouterr().err
