"""``hil emulate`` / ``python -m emulators`` as a lab uses them: stable port links that a restarted emulator
takes over, and the statistics on stderr and in the stats file at the end and on a signal."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial
import yaml

SWING = Path(__file__).resolve().parents[1] / "configs" / "emulated_swing.yaml"
KVH_HEADER = b"\xfe\x81\xff\x55"


def write_config(tmp_path: Path, imu: dict | None = None) -> Path:
    cfg = yaml.safe_load(SWING.read_text())
    cfg["imu"].update(imu or {})
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def start(command: list[str], config: Path, ports_file: Path, *extra: str) -> tuple[subprocess.Popen, dict]:
    """An emulator process at real time for 30 s at most, and its ports once it has written them."""
    proc = subprocess.Popen([sys.executable, "-m", *command, str(config), "--ports-file", str(ports_file),
                             "--speed", "1", "--duration", "30", *extra],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while not ports_file.exists():
        assert proc.poll() is None and time.monotonic() < deadline, "the emulator did not open its ports"
        time.sleep(0.05)
    return proc, json.loads(ports_file.read_text())


def stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> str:
    """Signal the emulator; its stderr once it has exited with 0."""
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == (0 if sig != signal.SIGKILL else -signal.SIGKILL), err
    return err


def kvh_bytes(path: str) -> bytes:
    """Half a second of what the port at ``path`` delivers."""
    with serial.Serial(path, 921600, timeout=0.05) as port:
        data, deadline = b"", time.monotonic() + 0.5
        while time.monotonic() < deadline:
            data += port.read(4096)
    return data


def test_link_dir_publishes_stable_links_that_a_restarted_emulator_takes_over(tmp_path):
    config, links = write_config(tmp_path), tmp_path / "by-id"
    first, ports = start(["emulators"], config, tmp_path / "first.json", "--link-dir", str(links))
    procs = [first]
    try:
        assert ports["imu"] == str(links / "imu") and ports["turntable_data"] == str(links / "turntable_data")
        ptys = {name: os.readlink(links / name) for name in ("imu", "turntable_data")}
        assert all(t.startswith("/dev/pts/") and Path(t).is_char_device() for t in ptys.values())
        assert ptys["imu"] != ptys["turntable_data"]

        second, again = start(["emulators"], config, tmp_path / "second.json", "--link-dir", str(links))
        procs.append(second)
        assert again["imu"] == ports["imu"]
        taken = {name: os.readlink(links / name) for name in ptys}
        assert all(taken[n] != ptys[n] and Path(taken[n]).is_char_device() for n in ptys)
        stop(first)  # the links are the second's now: the first leaves them
        assert {name: os.readlink(links / name) for name in ptys} == taken
        assert KVH_HEADER in kvh_bytes(ports["imu"])

        stop(second, signal.SIGKILL)  # no clean-up: the links dangle
        assert all(os.path.islink(links / n) and not os.path.exists(links / n) for n in ptys)
        third, _ = start(["emulators"], config, tmp_path / "third.json", "--link-dir", str(links))
        procs.append(third)
        assert KVH_HEADER in kvh_bytes(ports["imu"])  # a harness reopening DIR/imu finds the device again
        stop(third)
        assert not any(os.path.lexists(links / n) for n in ptys)  # its own links go with it
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()


@pytest.mark.parametrize(("command", "sig"), [(["hil.cli", "emulate"], signal.SIGTERM),
                                              (["emulators"], signal.SIGINT)], ids=["hil-sigterm", "emulators-sigint"])
def test_a_signal_prints_the_statistics_a_line_a_device_and_writes_them_as_json(tmp_path, command, sig):
    config = write_config(tmp_path, {"faults": {"drop_rate": 0.05}})
    stats_file = tmp_path / "stats.json"
    proc, ports = start(command, config, tmp_path / "ports.json", "--stats-file", str(stats_file))
    try:
        assert KVH_HEADER in kvh_bytes(ports["imu"])
    finally:
        err = stop(proc, sig)
    stats = json.loads(stats_file.read_text())
    assert stats["stopped"] and re.search(rf"^emulator: {stats['pulses']} pulses in [\d.]+ s, stopped$", err, re.M)
    for name, device in stats["devices"].items():
        faults = ", ".join(f"{kind} {n}" for kind, n in device["faults"].items() if n) or "none"
        assert (f"emulator: {name}: {device['frames']} frames written, {device['lost_unread']} lost unread, "
                f"faults: {faults}") in err.splitlines()
    imu = stats["devices"]["imu"]
    assert imu["frames"] > 0 and imu["faults"]["dropped"] > 0 and stats["devices"]["turntable_data"]["lost_unread"] > 0
    assert "{" not in err  # the JSON is in the file, not on stderr
