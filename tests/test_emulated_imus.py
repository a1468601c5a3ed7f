"""The Xsens MTData2 IMU on a pty and the CAN IMU on python-can buses, read by third-party tools."""

from __future__ import annotations

import math
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

import can
import cantools
import numpy as np
import pytest
import yaml
from tests.helpers import from_zero, interruptible
from test_emulated_devices import read_raw

from drivers.capture import decode_capture
from drivers.transport import open_can_bus
from emulators.in_process import EmulatorThread
from emulators.ports import CanPort
from emulators.process import EmulatorRun, spawn_emulator
from emulators.simulation import Simulation
from hil.config import ConfigError, parse_config

RATE = 200.0
HIGHRES = "configs/imu_lab_highres.dbc"
SWING = {"outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
         "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
         "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6}}


def trial(imu: dict, duration: float = 1.0) -> dict:
    return {"trial": {"name": "imus", "duration_s": duration, "rate_hz": RATE, "seed": 4},
            "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
            "turntable": from_zero({"motion": {"kind": "swing", "axes": SWING}}), "imu": from_zero(imu)}


def xsens_items(frame: bytes) -> dict[int, bytes]:
    """An MTData2 message by the Xbus text: FA FF 36 LEN payload CS, sum after FA = 0 mod 256."""
    assert frame[:3] == b"\xfa\xff\x36" and frame[3] < 0xFF and len(frame) == 5 + frame[3]
    assert sum(frame[1:]) % 256 == 0
    items, pos = {}, 4
    while pos < len(frame) - 1:
        xdi, size = struct.unpack_from(">HB", frame, pos)
        items[xdi] = frame[pos + 3:pos + 3 + size]
        pos += 3 + size
    return items


def test_xsens_on_a_pty_carries_counter_drifting_sample_time_and_increments(tmp_path):
    imu = {"protocol": "xsens-mtdata2", "latch_delay_us": 300, "timing": {"clock_drift_ppm": 500.0}}
    cfg = parse_config(trial(imu))
    out = {k: bytearray() for k in ("imu", "turntable_data")}
    with EmulatorThread(cfg) as emu:
        readers = [threading.Thread(target=read_raw, args=(emu.ports[k], buf)) for k, buf in out.items()]
        for r in readers:
            r.start()
        emu.join()
        for r in readers:
            r.join(5)
    data = out["imu"]
    size = 5 + data[3]
    frames = [bytes(data[i:i + size]) for i in range(0, len(data), size)]
    assert len(frames) == 200
    # error-free increments over the intervals that end 300 us after each pulse
    truth = Simulation.from_config(cfg).truth
    dtheta, dv = truth.increments(3e-4, np.arange(1, 201) / RATE + 3e-4)
    for k, frame in enumerate(frames, start=1):
        items = xsens_items(frame)
        assert struct.unpack(">H", items[0x1020])[0] == k
        # its clock runs 500 ppm fast: it reads (k / 200 + 3e-4) * 1.0005 s at the latch
        assert struct.unpack(">I", items[0x1060])[0] == round((k / RATE + 3e-4) * 1.0005 * 1e4)
        w, x, y, z = struct.unpack(">4f", items[0x8030])
        half = np.linalg.norm(dtheta[k - 1]) / 2
        assert w == pytest.approx(math.cos(half), abs=1e-7)
        np.testing.assert_allclose(np.array([x, y, z]) / math.sin(half) * half * 2, dtheta[k - 1], rtol=1e-5)
        np.testing.assert_allclose(struct.unpack(">3f", items[0x4010]), dv[k - 1], rtol=1e-6)


def can_trial(interface: str, channel: str, duration: float = 1.0) -> dict:
    return trial({"protocol": "can-dbc", "can": {"interface": interface, "channel": channel, "dbc": HIGHRES}},
                 duration)


def check_log(log, cfg, complete: bool = True) -> None:
    """The log decodes to the samples, and cantools reads the truth increments to the DBC's resolution.

    ``complete`` False: UDP may lose datagrams on a loaded host; what arrived must still be right.
    """
    counters = decode_capture("can-dbc", log, dbc=HIGHRES)
    if complete:
        assert counters == {"frames": 200, "corrupt": 0, "skipped_bytes": 0, "gaps": 0, "invalid": 0}
    db = cantools.database.load_file(HIGHRES)
    batch = next(Simulation.from_config(parse_config(cfg)).batches())
    dthetax = [db.decode_message(m.arbitration_id, m.data) for m in can.LogReader(str(log))
               if m.arbitration_id == 0x100]
    k = np.array([int(d["SyncCounter"]) for d in dthetax])
    assert len(k) >= (200 if complete else 100) and np.all(np.diff(k) > 0)
    assert np.max(np.abs(np.array([d["DThetaX"] for d in dthetax]) - batch.dtheta[k - 1, 0])) <= 0.5e-9 + 1e-15


def test_can_imu_on_the_in_process_virtual_bus_is_logged_to_blf(tmp_path):
    cfg = can_trial("virtual", "emulated-imu-test")
    bus = open_can_bus("virtual", "emulated-imu-test")
    log = tmp_path / "imu.blf"
    logger = can.Logger(str(log))
    try:
        with EmulatorThread(parse_config(cfg)) as emu:
            assert emu.ports["imu"] == {"interface": "virtual", "channel": "emulated-imu-test"}
            table = threading.Thread(target=read_raw, args=(emu.ports["turntable_data"], bytearray()))
            table.start()  # the pulse train starts once the table port has a reader
            received = 0
            while received < 6 * 200:
                message = bus.recv(5.0)
                assert message is not None
                logger.on_message_received(message)
                received += 1
            emu.join()
            table.join(5)
    finally:
        logger.stop()
        bus.shutdown()
    check_log(log, cfg)


@pytest.mark.usefixtures("udp_multicast_alone")
def test_can_imu_across_processes_on_udp_multicast_is_captured_by_the_can_logger(tmp_path):
    group = "239.74.163.91"
    config = tmp_path / "can.yaml"
    cfg = can_trial("udp_multicast", group)
    config.write_text(yaml.safe_dump(cfg))
    log = tmp_path / "imu.blf"
    logger = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "udp_multicast", "-c", group,
                               "--bus-kwargs", "hop_limit=0", "-f", str(log)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, preexec_fn=interruptible)
    try:
        time.sleep(3.0)  # the logger imports python-can and joins the group (a SIGINT before that is lost)
        proc, ports = spawn_emulator(config, tmp_path / "ports.json", EmulatorRun("2", wait_readers=True))
        assert ports["imu"] == {"interface": "udp_multicast", "channel": group}
        read_raw(ports["turntable_data"], bytearray())
        assert proc.wait(20) == 0
        time.sleep(0.3)
    finally:
        logger.send_signal(signal.SIGINT)
        logger.wait(30)
    check_log(log, cfg, complete=False)


@pytest.mark.parametrize(("group", "level", "option"), [
    ("239.74.163.92", socket.IPPROTO_IP, socket.IP_MULTICAST_TTL),
    ("ff15:7079:7468:6f6e:6465:6d6f:6d63:6173", socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS),
])
def test_the_emulators_can_socket_never_sends_off_the_host(group, level, option):
    port = CanPort("udp_multicast", group)
    try:
        assert port.bus._multicast._socket.getsockopt(level, option) == 0
    finally:
        port.close()


def test_a_line_too_slow_for_the_frames_is_refused():
    cfg = parse_config(dict(trial({}), turntable={"baudrate": 38400, "motion": {"kind": "swing", "axes": SWING}}))
    with pytest.raises(ConfigError, match=r"turntable.baudrate: 24-byte frames at 200 Hz need 48000 baud"):
        EmulatorThread(cfg)


def test_frames_are_written_when_their_last_byte_would_have_arrived():
    # 24 bytes at 57600 baud, 10 bits a byte: 4.17 ms on the wire after each pulse; 36 bytes at 921600: 0.39 ms
    cfg = parse_config(dict(trial({}, duration=0.5), turntable={"baudrate": 57600,
                                                                 "motion": {"kind": "swing", "axes": SWING}}))
    with EmulatorThread(cfg, speed=1.0) as emu:
        readers = [threading.Thread(target=read_raw, args=(emu.ports[k], bytearray())) for k in ("imu", "turntable_data")]
        for r in readers:
            r.start()
        stats = emu.join()
        for r in readers:
            r.join(5)
    table, imu = stats.devices["turntable_data"], stats.devices["imu"]
    # never sooner than the wire time after the pulse (a loaded machine only makes it later)
    assert table.latency_p50_ms >= 24 * 10 / 57600 * 1e3 and imu.latency_p50_ms >= 36 * 10 / 921600 * 1e3
