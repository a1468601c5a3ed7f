"""CAN side: DBC golden frames, a real python-can bus, python-can logs and cantools read what we write."""

from __future__ import annotations

import csv
import json
import math
import socket
import time

import can
import cantools
import pytest
from tests.helpers import Decoding

from drivers.can_dbc import CanDbcCodec
from drivers.capture import decode_capture
from drivers.codec import RawChunk
from drivers.decoder import StreamDecoder
from drivers.kvh1750 import STATUS_ALL_VALID, Kvh1750Codec
from drivers.reader import DeviceReader
from drivers.tap import CanLogTap
from drivers.transport import CanTransport, open_can_bus
from hil.cli import main
from hil.samples import ImuSample

HIGHRES = "configs/imu_lab_highres.dbc"
J1939 = "configs/imu_j1939.dbc"


def sample(i: int) -> ImuSample:
    return ImuSample(i, (1e-6 * i, -2e-6, 3.5e-7), (1e-4, -2e-4, 0.0490333), status=0)


def test_highres_frame_layout_matches_the_dbc_by_hand():
    # DThetaX = 1000 counts of 1e-9 rad, int32 LE; SyncCounter 0x123456 uint24 LE; Status 0.
    db = cantools.database.load_file(HIGHRES)
    values = db.decode_message(0x100, bytes.fromhex("E8030000 563412 00"))
    assert values["DThetaX"] == pytest.approx(1e-6) and values["SyncCounter"] == 0x123456
    codec = CanDbcCodec.for_dbc(HIGHRES, 200.0)
    messages = codec.encode(codec.from_sample(ImuSample(0x123456, (1e-6, 0, 0), (0, 0, 0))))
    assert [m.arbitration_id for m in messages] == [0x100, 0x101, 0x102, 0x103, 0x104, 0x105]
    assert all(len(m.data) == 8 and not m.is_extended_id for m in messages)
    assert bytes(messages[0].data) == bytes.fromhex("E8030000 563412 00")


def test_a_shipped_dbc_is_found_by_name_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in (J1939, "imu_j1939.dbc"):
        assert [m.name for m in CanDbcCodec.for_dbc(name, 100.0).messages] == ["ARI", "ACCS"]


def test_highres_resolution_is_within_the_design_bounds():
    db = cantools.database.load_file(HIGHRES)
    for message in db.messages:
        value = message.signals[0]
        assert value.length == 32 and value.is_signed
        assert value.scale <= (1e-9 if value.unit == "rad" else 1e-8)
        assert {"SyncCounter", "Status"} <= {s.name for s in message.signals}


def test_j1939_golden_frames_use_standard_scaling():
    db = cantools.database.load_file(J1939)
    ari, accs = db.get_message_by_name("ARI"), db.get_message_by_name("ACCS")
    assert (ari.frame_id >> 8) & 0x3FFFF == 61482 and (accs.frame_id >> 8) & 0x3FFFF == 61485
    assert ari.is_extended_frame and accs.is_extended_frame
    # Pitch rate 10 deg/s: (10 + 250) * 128 = 0x8200; vertical 9.81 m/s^2: (9.81 + 320) / 0.01 = 0x80D5.
    rates = ari.decode(bytes.fromhex("0082 007D 007D FFFF"))
    assert rates["PitchRate"] == pytest.approx(10.0) and rates["RollRate"] == pytest.approx(0.0)
    accel = accs.decode(bytes.fromhex("007D 007D D580 FFFF"))
    assert accel["VerticalAcceleration"] == pytest.approx(9.81) and accel["LateralAcceleration"] == pytest.approx(0.0)


def test_j1939_rates_become_increments_with_the_imu_rate():
    codec = CanDbcCodec.for_dbc(J1939, 100.0)
    framer = codec.framer()
    first = framer.feed_chunk(RawChunk("imu", 1.0, bytes.fromhex("0082 007D 007D FFFF"), codec.messages[0].frame_id,
                                        True))
    imu = codec.samples(framer.feed_chunk(RawChunk("imu", 1.0, bytes.fromhex("007D 007D D580 FFFF"),
                                                   codec.messages[1].frame_id, True)))
    assert len(first) == 0 and len(imu) == 1
    assert imu.dtheta[0] == pytest.approx((math.radians(10) / 100, 0.0, 0.0))
    assert imu.dv[0] == pytest.approx((0.0, 0.0, 9.81 / 100))


def test_session_on_a_virtual_bus_decodes_samples_and_logs_what_python_can_reads(tmp_path):
    codec = CanDbcCodec.for_dbc(HIGHRES, 200.0)
    log = tmp_path / "imu.blf"
    sink = Decoding(codec)
    channel = "drivers-test-virtual"
    session = DeviceReader(CanTransport("virtual", channel, "imu"), [sink, CanLogTap(log)]).start()
    sender = open_can_bus("virtual", channel)
    sent = []
    try:
        sender.send(can.Message(arbitration_id=0x7FF, data=b"\x01", is_extended_id=False))  # foreign traffic
        for i in range(20):
            for message in codec.encode(codec.from_sample(sample(i))):
                sender.send(message)
                sent.append(message)
        deadline = time.monotonic() + 5
        while len(sink.samples) < 20 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        sender.shutdown()
        session.stop()
    assert [s.sync_index for s in sink.samples] == list(range(20))
    assert sink.samples[7].dtheta == pytest.approx((7e-6, -2e-6, 3.5e-7), abs=1e-9)
    assert sink.samples[7].dv == pytest.approx((1e-4, -2e-4, 0.0490333), abs=1e-8)
    assert len(sink.raw) == 121 and sink.counters.skipped_bytes == 1

    logged = [m for m in can.LogReader(str(log))]
    assert [(m.arbitration_id, bytes(m.data)) for m in logged[1:]] == [(m.arbitration_id, bytes(m.data)) for m in sent]
    db = cantools.database.load_file(HIGHRES)
    decoded = db.decode_message(logged[1 + 6 * 5].arbitration_id, logged[1 + 6 * 5].data)
    assert decoded["DThetaX"] == pytest.approx(5e-6) and decoded["SyncCounter"] == 5

    out = tmp_path / "imu.csv"
    counters = decode_capture("can-dbc", log, out)
    assert counters == {"frames": 20, "corrupt": 0, "skipped_bytes": 1, "gaps": 0, "invalid": 0}
    rows = list(csv.reader(out.open()))
    assert rows[0][:2] == ["sync_index", "gyro_x_rad"] and len(rows) == 21
    assert float(rows[6][1]) == pytest.approx(5e-6)


def test_decode_reads_an_asc_written_by_python_can_logger(tmp_path):
    codec = CanDbcCodec.for_dbc(J1939, 100.0)
    path = tmp_path / "j1939.asc"
    logger = can.Logger(str(path))
    for i in range(10):
        imu = ImuSample(i, (math.radians(i) / 100, 0.0, 0.0), (0.0, 0.0, 0.0981))
        for k, message in enumerate(codec.encode(codec.from_sample(imu))):
            message.timestamp = 1000.0 + i * 0.01 + k * 1e-4
            logger.on_message_received(message)
    logger.stop()
    out = tmp_path / "j1939.csv"
    assert decode_capture("can-dbc", path, out, dbc=J1939) == {"frames": 10, "corrupt": 0, "skipped_bytes": 0,
                                                               "gaps": 0, "invalid": 0}
    rows = list(csv.DictReader(out.open()))
    assert [int(r["sync_index"]) for r in rows] == list(range(10))
    assert float(rows[4]["gyro_x_deg_s"]) == pytest.approx(4.0, abs=1 / 128)
    assert float(rows[4]["accel_z_m_s2"]) == pytest.approx(9.81, abs=0.01)


def test_decode_command_prints_counters_as_json_on_the_last_line(tmp_path, capsys):
    codec = Kvh1750Codec(rate_hz=1000)
    frames = [codec.encode(codec.from_sample(ImuSample(i, (1e-6, 0, 0), (0, 0, 0.0098), status=STATUS_ALL_VALID)))
              for i in range(130)]
    damaged = bytearray(frames[50])
    damaged[20] ^= 0x01
    dump = tmp_path / "kvh.bin"
    dump.write_bytes(b"\x00\x01" + b"".join(frames[:50]) + bytes(damaged) + b"".join(frames[51:]))
    assert main(["decode", "kvh1750", str(dump), "--out", str(tmp_path / "kvh.csv")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert json.loads(lines[-1]) == {"frames": 129, "corrupt": 1, "skipped_bytes": 38, "gaps": 1, "invalid": 0}
    rows = list(csv.reader((tmp_path / "kvh.csv").open()))
    assert rows[0][:2] == ["sync_index", "gyro_x_rad"] and "accel_x_g" in rows[0]
    assert [int(r[0]) for r in rows[1:]][48:52] == [48, 49, 51, 52]
    assert int(rows[-1][0]) == 129  # the 7-bit sequence unwrapped past 127


def test_udp_multicast_bus_never_leaves_the_host():
    bus = open_can_bus("udp_multicast", "239.74.163.77")
    try:
        assert bus._multicast._socket.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
    finally:
        bus.shutdown()


def test_a_can_bus_gets_a_receive_buffer_for_seconds_of_a_2khz_imu():
    bus = open_can_bus("udp_multicast", "239.74.163.78")
    try:
        granted = bus._multicast._socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    finally:
        bus.shutdown()
    # as root past net.core.rmem_max; otherwise capped by it (the kernel doubles what it grants)
    cap = 2 * int(open("/proc/sys/net/core/rmem_max").read())
    assert granted >= min(2 * (1 << 23), cap)


def test_a_can_read_takes_every_message_waiting_and_the_decoder_groups_them_by_read_tick():
    codec = CanDbcCodec.for_dbc(HIGHRES, 1000.0)
    channel = "drivers-test-batch"
    transport, sender = CanTransport("virtual", channel, "imu"), open_can_bus("virtual", channel)
    transport.open()
    try:
        for i in range(50):
            for message in codec.encode(codec.from_sample(sample(i))):
                sender.send(message)
        chunks = transport.read()
    finally:
        sender.shutdown()
        transport.close()
    assert len(chunks) == 300  # one read: every message already on the bus

    decoder = StreamDecoder(codec, read_s=0.05)
    # the receive times of 50 samples at 1 kHz from t = 10.0205 s: ticks of 50 ms end at 10.05 s and 10.10 s
    ticks = []
    for k, chunk in enumerate(chunks):
        out = decoder.feed(RawChunk("imu", 10.0205 + 1e-3 * (k // 6), chunk.data, chunk.arbitration_id,
                                    chunk.is_extended_id))
        if out is not None:
            ticks.append((k, [int(i) for i in out.sync_index]))
    assert ticks == [(6 * 30, list(range(30)))]  # the first message of 10.05 s releases those before
    assert [int(i) for i in decoder.flush().sync_index] == list(range(30, 50)) and decoder.flush() is None


def test_cantools_decode_command_reads_our_frames():
    """The third-party `cantools decode` command, fed candump lines of what our encoder sends."""
    import subprocess
    import sys

    codec = CanDbcCodec.for_dbc(HIGHRES, 200.0)
    lines = [
        f"  vcan0  {m.arbitration_id:03X}   [{m.dlc}]  {' '.join(f'{b:02X}' for b in m.data)}"
        for m in codec.encode(codec.from_sample(sample(5)))
    ]
    proc = subprocess.run(
        [sys.executable, "-m", "cantools", "decode", HIGHRES], input="\n".join(lines) + "\n",
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert "DThetaX: 5e-06 rad" in proc.stdout
    assert proc.stdout.count("SyncCounter: 5") == len(lines)


@pytest.mark.usefixtures("udp_multicast_alone")
def test_a_udp_multicast_bus_receives_only_its_own_group():
    import can

    first, second = open_can_bus("udp_multicast", "239.74.163.78"), open_can_bus("udp_multicast", "239.74.163.79")
    try:
        first.send(can.Message(arbitration_id=0x78, data=b"\x01", is_extended_id=False))
        second.send(can.Message(arbitration_id=0x79, data=b"\x02", is_extended_id=False))
        got = {bus: [] for bus in (first, second)}
        for bus in (first, second):
            while (message := bus.recv(timeout=0.5)) is not None:
                got[bus].append(message.arbitration_id)
        assert got[first] == [0x78] and got[second] == [0x79]
    finally:
        first.shutdown()
        second.shutdown()
