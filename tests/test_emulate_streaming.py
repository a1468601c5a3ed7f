"""``hil emulate`` behaves like powered hardware: every port streams whether or not anyone reads it."""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import subprocess
import sys
import termios
import time
from pathlib import Path

import can
import pytest
import serial
import yaml
from emulators.in_process import EmulatorThread
from hil.config import parse_config
from tests.helpers import interruptible
from test_emulated_shutdown import CONFIG, tts1_counters

KVH_HEADER = b"\xfe\x81\xff\x55"


def _emulate(tmp_path: Path, cfg: dict, *extra: str) -> tuple[subprocess.Popen, dict, Path]:
    config, ports_file, stats = tmp_path / "c.yaml", tmp_path / "ports.json", tmp_path / "stats.json"
    config.write_text(yaml.safe_dump(cfg))
    proc = subprocess.Popen([sys.executable, "-m", "emulators", str(config), "--ports-file", str(ports_file),
                             "--stats-file", str(stats), *extra], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 20
    while not ports_file.exists():
        assert proc.poll() is None and time.monotonic() < deadline, "the emulator did not open its ports"
        time.sleep(0.05)
    return proc, json.loads(ports_file.read_text()), stats


def _stop(proc: subprocess.Popen, stats: Path) -> dict:
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(20) == 0
    return json.loads(stats.read_text())


def test_a_reader_on_the_imu_port_alone_gets_every_frame_while_the_unread_table_port_drops_its_own(tmp_path):
    """The rate itself is measured in benchmarks/emulator_timing.py; here the emulator's own counts: both
    devices run on the one pulse train, so the table drops what the IMU writes, and the reader loses nothing."""
    proc, ports, stats_file = _emulate(tmp_path, CONFIG)
    try:
        with serial.Serial(ports["imu"], 921600, timeout=0.05) as imu:  # nobody opens the table port
            imu.read(1 << 16)  # what arrived before the first timed read
            data = b""
            while len(data) < 3 * 200 * 36:  # three seconds of frames
                data += imu.read(4096)
        frames = [data[i:i + 36] for i in range(data.find(KVH_HEADER), len(data) - 35, 36)]
        counters = [f[29] for f in frames if f.startswith(KVH_HEADER)]
    finally:
        stats = _stop(proc, stats_file)
    assert len(counters) == len(frames) and len(frames) > 0
    assert all((b - a) % 128 == 1 for a, b in zip(counters, counters[1:]))  # consecutive: nothing lost
    imu_stats, table = stats["devices"]["imu"], stats["devices"]["turntable_data"]
    assert imu_stats["frames"] >= len(frames)  # (and lost unread only before the port was opened)
    emitted = imu_stats["frames"] + imu_stats["lost_unread"]
    assert table["frames"] == 0 and abs(table["lost_unread"] - emitted) <= 2  # the same pulses, every one dropped


@pytest.mark.usefixtures("udp_multicast_alone")
def test_python_can_logger_in_another_process_captures_the_default_emulated_can_imu(tmp_path):
    cfg = dict(CONFIG, imu={"protocol": "can-dbc"})  # no imu.can block: the default bus
    log = tmp_path / "imu.asc"
    logger = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "udp_multicast", "-c", "239.74.163.2",
                               "--bus-kwargs", "hop_limit=0", "-f", str(log)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, preexec_fn=interruptible)
    try:
        time.sleep(3.0)  # the logger imports python-can and joins the group (a SIGINT before that is lost)
        proc, ports, stats_file = _emulate(tmp_path, cfg)
        assert ports["imu"] == {"interface": "udp_multicast", "channel": "239.74.163.2"}
        time.sleep(2.0)
        stats = _stop(proc, stats_file)
    finally:
        logger.send_signal(signal.SIGINT)
        logger.wait(30)
    messages = list(can.LogReader(str(log)))
    samples = stats["devices"]["imu"]["frames"]  # one sample is a message per DBC message id
    per_sample = len({m.arbitration_id for m in messages})
    assert samples > 0 and per_sample >= 2
    # UDP has no flow control: a logger starved of CPU on a loaded host loses datagrams, never gains any
    assert 0.5 * samples * per_sample <= len(messages) <= samples * per_sample


@pytest.mark.usefixtures("udp_multicast_alone")
def test_hil_run_reads_the_default_emulated_can_imu_from_the_emulators_process(tmp_path):
    from hil.cli import main

    cfg = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs" / "emulated_swing.yaml").read_text())
    cfg["imu"] = {**cfg["imu"], "protocol": "can-dbc"}  # no imu.can block: the default bus
    config = tmp_path / "can.yaml"
    config.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    code = main(["run", str(config), "--duration", "6", "--quiet", "--viewer", "none", "--no-figures",
                 "--out", str(out)])  # real time: UDP has no flow control, a reader far behind loses datagrams
    result = json.loads((out / "result.json").read_text())
    assert code == 3 and result["ended"] == "completed"  # 6 s cannot meet the default trial's 600 s limits
    # UDP has no flow control: with the suite's other worker busy beside it, a few % of the datagrams can go
    # (1128 of 1200 seen); a harness that fell behind for good would lose far more
    assert result["streams"]["imu_frames"] >= 0.9 * 1200 and result["estimate"]["gram_rank"] == 12


def test_readers_slow_to_set_their_ports_up_lose_no_frame_to_their_own_flush():
    """Held for its readers (``--wait-readers``, the harness's own emulator), the pulse train waits until each
    reader has emptied its input, as a serial library does on opening a port: a frame written before that
    flush would be lost to it. The readers here hold the ports open, set their lines up and only then, half a
    second later each time (a host busy elsewhere), flush."""
    cfg = parse_config({**CONFIG, "trial": {**CONFIG["trial"], "duration_s": 2.0}})
    names = ("imu", "turntable_data")
    with EmulatorThread(cfg, speed=None, duration=2.0) as emulator:
        fds = {name: os.open(emulator.ports[name], os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK) for name in names}
        try:
            time.sleep(0.5)
            for fd in fds.values():
                attrs = termios.tcgetattr(fd)
                attrs[4] = attrs[5] = termios.B921600
                termios.tcsetattr(fd, termios.TCSANOW, attrs)
            time.sleep(0.5)
            for fd in fds.values():
                termios.tcflush(fd, termios.TCIFLUSH)
            data = dict.fromkeys(names, b"")
            while emulator.thread.is_alive():  # it drains its ports into the readers before it closes them
                select.select(list(fds.values()), [], [], 0.02)
                for name, fd in fds.items():
                    with contextlib.suppress(BlockingIOError, OSError):  # EIO: closed after its last frame
                        data[name] += os.read(fd, 1 << 16)
            stats = emulator.join()
        finally:
            for fd in fds.values():
                os.close(fd)
    kvh = data["imu"]
    assert kvh.startswith(KVH_HEADER) and kvh.count(KVH_HEADER) == stats.devices["imu"].frames == 400
    counters = tts1_counters(data["turntable_data"])
    assert len(counters) == stats.devices["turntable_data"].frames == 400
    assert counters == list(range(counters[0], counters[0] + 400))  # from the first pulse, none missing
