"""``hil emulate`` in its own process: a third-party terminal reads it; Ctrl-C or SIGTERM leaves nothing behind."""

from __future__ import annotations

import os
import select
import signal
import socket
import struct
import subprocess
import sys
import time
import tty
from pathlib import Path

import pytest
import serial
import yaml
from crccheck.crc import Crc16Xmodem

from emulators.process import EmulatorRun, spawn_emulator

CONFIG = {"trial": {"name": "shutdown", "duration_s": 600.0, "rate_hz": 200.0, "seed": 1},
          "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
          "turntable": {"motion": {"kind": "swing", "axes": {"inner": {"amplitude_deg": 13, "period_s": 8}}}}}


def tts1_counters(data: bytes) -> list[int]:
    """Sync counters of the tts1 frames in ``data``, each checked by the protocol text (CRC-16/XMODEM)."""
    out, pos = [], data.find(b"TS\x01")
    while 0 <= pos <= len(data) - 24:
        frame = data[pos:pos + 24]
        assert struct.unpack(">H", frame[22:])[0] == Crc16Xmodem.calc(frame[2:22])
        out.append(struct.unpack_from("<I", frame, 4)[0])
        pos = data.find(b"TS\x01", pos + 24)
    return out


@pytest.fixture
def emulator(tmp_path: Path):
    config = tmp_path / "emulated.yaml"
    config.write_text(yaml.safe_dump(CONFIG))
    proc, ports = spawn_emulator(config, tmp_path / "ports.json", EmulatorRun("1", wait_readers=True))
    yield proc, ports, tmp_path / "ports.json"
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def test_pyserial_miniterm_reads_the_emulated_table_stream(emulator):
    _, ports, _ = emulator
    console, console_slave = os.openpty()  # miniterm wants a terminal for its console
    tty.setraw(console_slave)
    imu = serial.Serial(ports["imu"], timeout=0.05)  # the pulse train starts once both ports have a reader
    term = subprocess.Popen([sys.executable, "-m", "serial.tools.miniterm", "--raw", "-q", ports["turntable_data"],
                             "115200"], stdin=console_slave, stdout=console_slave, stderr=subprocess.DEVNULL)
    try:
        data, deadline = b"", time.monotonic() + 10
        while len(data) < 24 * 60 and time.monotonic() < deadline:
            imu.read(4096)
            if select.select([console], [], [], 0.05)[0]:
                data += os.read(console, 4096)
        os.write(console, b"\x1d")  # Ctrl-] ends miniterm
        assert term.wait(5) == 0
    finally:
        imu.close()
        if term.poll() is None:
            term.kill()
        os.close(console)
        os.close(console_slave)
    counters = tts1_counters(data)
    assert len(counters) >= 50 and counters == list(range(counters[0], counters[0] + len(counters)))


def children_of(pid: int) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry))
    return found


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_a_signal_closes_the_ptys_and_releases_the_command_port(emulator, sig):
    proc, ports, ports_file = emulator
    host, port = ports["turntable_cmd"].removeprefix("socket://").split(":")
    with socket.create_connection((host, int(port)), timeout=2) as conn:  # a client still connected
        conn.sendall(b"*IDN?\r\n")
        assert conn.recv(100)[8:].startswith(b"turntable-hil")  # after the error code and length
        with serial.Serial(ports["imu"], timeout=0.05) as imu, serial.Serial(ports["turntable_data"],
                                                                              timeout=0.05) as table:
            got, deadline = b"", time.monotonic() + 5
            while len(got) < 24 * 20 and time.monotonic() < deadline:
                got += table.read(4096)
                imu.read(4096)
            assert len(got) >= 24 * 20 and children_of(proc.pid) == []
            proc.send_signal(sig)
            assert proc.wait(5) == 0
            with pytest.raises(serial.SerialException):
                for _ in range(100):
                    table.read(4096)
        assert conn.recv(100) == b""  # the server closed the connection
    assert not any(os.path.exists(p) for p in (ports["imu"], ports["turntable_data"]))
    assert not ports_file.exists()
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((host, int(port)), timeout=2).close()
    with socket.create_server((host, int(port))):  # the port is free again
        pass


def _gone(pid: int) -> bool:
    """The process has exited (reaped, or a zombie no one has reaped yet)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


def test_an_emulator_whose_harness_is_killed_writes_nothing_more_in_the_harness_directory(tmp_path):
    """A harness killed outright (a plan killed mid-step): its emulator stops on its death signal without writing
    its statistics there, where a harness resumed at once may have started its own; it removes its ports file."""
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(CONFIG))
    stats, ports = tmp_path / "emulator.json", tmp_path / "ports.json"
    script = ("import time\nfrom pathlib import Path\nfrom emulators.process import EmulatorRun, spawn_emulator\n"
              f"run = EmulatorRun('1', wait_readers=True, hold=True, stats_file=Path({str(stats)!r}))\n"
              f"proc, _ = spawn_emulator(Path({str(config)!r}), Path({str(ports)!r}), run)\n"
              "print(proc.pid, flush=True)\ntime.sleep(600)\n")
    harness = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                               cwd=Path(__file__).resolve().parents[1])
    emulator = int(harness.stdout.readline())
    harness.kill()
    harness.wait()
    deadline = time.monotonic() + 30
    while not _gone(emulator) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _gone(emulator), "the emulator outlived its harness"
    assert not stats.exists() and not ports.exists()
