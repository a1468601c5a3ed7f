"""Ports as lab engineers write them: the emulated devices behind a real ser2net, and ports nobody serves."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest
import yaml

from drivers.acutrol_controller import AcutrolController
from drivers.table_controller import TableError
from drivers.transport import SerialTransport, TransportError, serial_url
from emulators.process import EmulatorRun, spawn_emulator
from hil.cli import main
from hil.config import load_config

ROOT = Path(__file__).resolve().parents[1]
EMULATED = ROOT / "configs" / "emulated_swing.yaml"
SER2NET = shutil.which("ser2net", path=os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin"]))
# ser2net's YAML needs a name (&alias) on every connection, and repeats the key "connection"
SER2NET_CONFIG = """\
%YAML 1.1
---
connection: &imu
  accepter: tcp,127.0.0.1,{imu_tcp}
  connector: serialdev,{imu_pty},{imu_baud}n81,local
connection: &table
  accepter: telnet(rfc2217),tcp,127.0.0.1,{table_tcp}
  connector: serialdev,{table_pty},{table_baud}n81,local
"""


def emulated_config() -> dict:
    """The shipped emulated swing with an Xsens IMU, whose 16-bit packet counter sizes any pause of a loaded
    host (a KVH's 7-bit counter wraps every 0.64 s at 200 Hz: a 0.4 s stall reads as 128 lost frames)."""
    cfg = yaml.safe_load(EMULATED.read_text())
    cfg["imu"]["protocol"] = "xsens-mtdata2"
    return cfg


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def open_files(pid: int) -> set[str]:
    """What process ``pid`` holds open: paths, and ``socket:[inode]`` for its sockets."""
    held = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            held.add(os.readlink(fd))
        except OSError:
            continue  # closed meanwhile
    return held


def listening_ports(pid: int) -> set[int]:
    """The local TCP ports process ``pid`` listens on."""
    held = open_files(pid)
    ports = set()
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        fields = line.split()
        if fields[3] == "0A" and f"socket:[{fields[9]}]" in held:  # 0A: LISTEN
            ports.add(int(fields[1].rsplit(":", 1)[1], 16))
    return ports


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait()


@pytest.fixture
def ser2net_binary() -> str:
    if SER2NET is None:
        pytest.skip("the ser2net binary is not installed (apt-get install ser2net; .ci/run does)")
    return SER2NET


@pytest.fixture
def emulator(tmp_path: Path):
    """The emulated devices at real-time speed, running longer than any trial here; their ports."""
    config = tmp_path / "emulated.yaml"
    config.write_text(yaml.safe_dump(emulated_config()))
    proc, ports = spawn_emulator(config, tmp_path / "ports.json", EmulatorRun("1", 120.0, wait_readers=True),
                                 log_file=tmp_path / "emulator.log")
    try:
        yield ports
    finally:
        stop(proc)


@pytest.fixture
def ser2net(ser2net_binary: str, emulator, tmp_path: Path):
    """Our own ser2net on 127.0.0.1 (no UUCP locks in /var/lock: -u): the IMU pty as raw TCP, the table's
    data pty as telnet/RFC 2217. Returns the process and the two TCP ports."""
    cfg = load_config(tmp_path / "emulated.yaml")
    tcp = {"imu_tcp": free_port(), "table_tcp": free_port()}
    config = tmp_path / "ser2net.yaml"
    config.write_text(SER2NET_CONFIG.format(**tcp, imu_pty=emulator["imu"], table_pty=emulator["turntable_data"],
                                            imu_baud=cfg.imu.baudrate, table_baud=cfg.turntable.baudrate))
    with open(tmp_path / "ser2net.log", "wb") as log:
        proc = subprocess.Popen([ser2net_binary, "-n", "-d", "-u", "-c", str(config)], stdout=log,
                                stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 10.0
        while not set(tcp.values()) <= listening_ports(proc.pid):
            assert proc.poll() is None and time.monotonic() < deadline, \
                f"ser2net did not listen on {tcp}: {(tmp_path / 'ser2net.log').read_text()}"
            time.sleep(0.05)
        yield proc, tcp["imu_tcp"], tcp["table_tcp"]
    finally:
        stop(proc)


def test_a_lab_trial_through_ser2net_raw_tcp_and_plain_rfc2217(ser2net, tmp_path):
    proc, imu_tcp, table_tcp = ser2net
    # ser2net opens a device only when a client connects: the emulator's pulse train waits for the trial
    assert not any(path.startswith("/dev/pts/") for path in open_files(proc.pid))
    cfg = emulated_config()
    cfg["imu"].update(source="serial", port=f"socket://127.0.0.1:{imu_tcp}")
    cfg["turntable"].update(source="serial", data_port=f"rfc2217://127.0.0.1:{table_tcp}")  # no query
    config, out = tmp_path / "lab.yaml", tmp_path / "run"
    config.write_text(yaml.safe_dump(cfg))
    code = main(["run", str(config), "--duration", "5", "--quiet", "--viewer", "none", "--no-figures",
                 "--out", str(out)])
    result = json.loads((out / "result.json").read_text())
    assert code == 3 and result["ended"] == "completed"  # 5 s cannot meet the default trial's 600 s limits
    assert result["trial"]["samples"] == 5 * cfg["trial"]["rate_hz"]
    streams = result["streams"]
    # every frame decoded is aligned, or was unpaired, late for its slot, or after the table's last angles at the
    # end; the read that ends the trial may carry a few beyond it, not estimated
    assert streams["aligned"] >= result["trial"]["samples"]
    assert streams["imu_frames"] <= streams["aligned"] + streams["aligner_after_table_end"] + streams["imu_unpaired"] \
        + streams["aligner_imu_late"]
    assert streams["table_frames"] > 0 and streams["sync_offset_ms"] is not None  # matched by sync counter
    # raw TCP loses nothing; over RFC 2217 ser2net's purge at connect may, rarely, still take a table frame
    assert streams["corrupt"] == streams["imu_missing"] == streams["imu_outages"] == streams["table_outages"] == 0


@pytest.fixture
def unserved_port():
    """A local TCP port held bound but not listening: every connection to it is refused."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        yield sock.getsockname()[1]


@pytest.mark.parametrize("scheme", ["socket", "rfc2217"])
def test_a_port_nobody_serves_is_a_one_line_error_naming_the_url(unserved_port, scheme):
    url = f"{scheme}://127.0.0.1:{unserved_port}"
    with pytest.raises(TransportError) as stream:
        SerialTransport(url, 921600, "imu").open()
    with pytest.raises(TableError) as command:
        AcutrolController(url, limits=None).open()
    assert str(stream.value) == f"imu: cannot open {url}: connection refused"
    assert str(command.value) == f"turntable command port: cannot open {url}: connection refused"


@pytest.mark.parametrize(("url", "opened"), [
    ("rfc2217://lab:2001", "rfc2217://lab:2001?ign_set_control"),
    ("rfc2217://lab:2001?timeout=5", "rfc2217://lab:2001?timeout=5&ign_set_control"),
    ("rfc2217://lab:2001?ign_set_control&timeout=3", "rfc2217://lab:2001?ign_set_control&timeout=3"),
    ("socket://lab:4001", "socket://lab:4001"),
    ("/dev/ttyUSB0", "/dev/ttyUSB0"),
])
def test_rfc2217_urls_get_ign_set_control_unless_they_say_so(url, opened):
    assert serial_url(url) == opened
