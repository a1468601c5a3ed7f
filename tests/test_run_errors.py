"""``hil run`` explains what is wrong in one line (exit 2), or ends a trial that cannot work (exit 1)."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest
import yaml

from emulators.process import EmulatorRun, spawn_emulator
from hil.cli import main

ROOT = Path(__file__).resolve().parents[1]
FAST = ["--speed", "max", "--quiet", "--viewer", "none", "--no-figures"]


def _config(tmp_path: Path, name: str, **sections) -> Path:
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    for section, values in sections.items():
        cfg.setdefault(section, {}).update(values)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hil: error: "), err
    return lines[0]


def test_a_config_the_emulator_rejects_is_one_line_with_its_reason(tmp_path, capsys):
    config = _config(tmp_path, "slow-line", imu={"baudrate": 9600})
    assert main(["run", str(config), "--duration", "5", *FAST, "--out", str(tmp_path / "out")]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "imu.baudrate" in line and "9600" in line


@pytest.mark.parametrize(("block", "rate", "key"), [("imu", {"rate_hz": 1000.0, "baudrate": 115200}, "imu.baudrate"),
                                                    ("turntable", {"baudrate": 9600}, "turntable.baudrate")])
def test_a_real_line_too_slow_for_its_frames_is_refused_before_reading(tmp_path, capsys, block, rate, key):
    """KVH 1750 frames of 36 bytes at 1 kHz need 360 000 baud; tts1 frames of 24 bytes at 200 Hz need 48 000."""
    server = socket.create_server(("127.0.0.1", 0))
    url = f"socket://127.0.0.1:{server.getsockname()[1]}"
    try:
        config = _config(tmp_path, "real-slow", imu={"source": "serial", "port": url},
                         turntable={"source": "serial", "data_port": url})
        cfg = yaml.safe_load(config.read_text())
        cfg[block].update(rate)
        config.write_text(yaml.safe_dump(cfg))
        assert main(["run", str(config), "--duration", "5", "--viewer", "none", "--quiet", "--out",
                     str(tmp_path / "out")]) == 2
    finally:
        server.close()
    line = _one_line(capsys.readouterr().err)
    assert key in line and "baud" in line, line


def test_an_emulated_can_imu_on_the_in_process_virtual_bus_is_refused(tmp_path, capsys):
    config = _config(tmp_path, "virtual", imu={"protocol": "can-dbc", "can": {"interface": "virtual"}})
    assert main(["run", str(config), "--duration", "5", *FAST, "--out", str(tmp_path / "out")]) == 2
    assert "imu.can.interface" in _one_line(capsys.readouterr().err)


def test_a_port_that_cannot_be_opened_is_one_line_with_its_url(tmp_path, capsys):
    config = _config(tmp_path, "lab", imu={"source": "serial", "port": "/dev/ttyNOSUCH0"},
                     turntable={"source": "serial", "data_port": "/dev/ttyNOSUCH1"})
    assert main(["run", str(config), "--duration", "5", *FAST, "--out", str(tmp_path / "out")]) == 2
    assert "/dev/ttyNOSUCH" in _one_line(capsys.readouterr().err)


def test_every_sample_rejected_for_five_seconds_ends_the_trial_naming_the_unit_key(tmp_path, capsys):
    device = _config(tmp_path, "device", imu={"options": {"accel_unit": "g"}})
    proc, ports = spawn_emulator(device, tmp_path / "ports.json", EmulatorRun("max", 60.0, wait_readers=True))
    try:
        harness = _config(tmp_path, "harness", imu={"source": "serial", "port": ports["imu"],
                                                     "options": {"accel_unit": "m/s^2"}},
                          turntable={"source": "serial", "data_port": ports["turntable_data"]})
        out = tmp_path / "out"
        assert main(["run", str(harness), "--duration", "60", *FAST, "--out", str(out)]) == 1
    finally:
        proc.kill()
        proc.wait()
    err = capsys.readouterr().err
    assert "imu.options.accel_unit" in err and "rejected" in err
    result = yaml.safe_load((out / "result.json").read_text())
    assert result["ended"].startswith("early: every IMU sample") and result["trial"]["duration_s"] < 10


def test_a_viewer_that_fails_to_start_is_one_line_and_leaves_no_emulator_behind(tmp_path, capsys, monkeypatch):
    import hil.trial.rig
    import hil.viewer.trial_viewer

    def broken(*args, **kwargs):
        raise OSError("rerun: address already in use")

    spawned = []

    def spawn(*args, **kwargs):
        spawned.append(spawn_emulator(*args, **kwargs))
        return spawned[-1]

    monkeypatch.setattr(hil.viewer.trial_viewer, "TrialViewer", broken)
    monkeypatch.setattr(hil.trial.rig, "spawn_emulator", spawn)
    out = tmp_path / "out"
    code = main(["run", str(ROOT / "configs" / "emulated_swing.yaml"), "--duration", "5", "--speed", "max",
                 "--quiet", "--viewer", "save", "--no-figures", "--out", str(out)])
    assert code == 2
    line = _one_line(capsys.readouterr().err)
    assert "--viewer save: the viewer did not start: rerun: address already in use" in line
    assert len(spawned) == 1 and spawned[0][0].poll() is not None  # spawned, then stopped
    assert not out.exists()  # refused at its start: no outputs


def test_swapped_ports_end_the_trial_with_one_line_naming_the_port(tmp_path, capsys):
    device = _config(tmp_path, "device")
    proc, ports = spawn_emulator(device, tmp_path / "ports.json", EmulatorRun("1", 30.0))  # streams as hardware
    try:
        lab = yaml.safe_load((ROOT / "configs" / "lab_swing.yaml").read_text())
        lab["imu"]["port"] = ports["turntable_data"]
        lab["turntable"]["data_port"] = ports["imu"]
        del lab["turntable"]["command_port"]
        harness = tmp_path / "swapped.yaml"
        harness.write_text(yaml.safe_dump(lab))
        out = tmp_path / "out"
        started = time.monotonic()
        assert main(["run", str(harness), "--quiet", "--viewer", "none", "--no-figures", "--out", str(out)]) == 1
        took = time.monotonic() - started
    finally:
        proc.kill()
        proc.wait()
    lines = capsys.readouterr().err.strip().splitlines()
    swapped = "are the IMU and table ports swapped?"
    unchecked = f"hil: WARNING: imu: no answer to '=CONFIG,1' within 1 s on {ports['turntable_data']}"
    assert len(lines) == 2 and lines[0].startswith(unchecked) and lines[1] in (  # whichever stream's 5 s run out first
        f"hil: trial early: the imu port ({ports['turntable_data']}) carries tts1 frames: {swapped}",
        f"hil: trial early: the turntable data port ({ports['imu']}) carries kvh1750 frames: {swapped}"), lines
    assert took < 13.0  # the IMU's configuration query (1 s), output.stream_timeout_s (5 s), the start and outputs
    result = yaml.safe_load((out / "result.json").read_text())
    assert result["ended"] == f"early: {lines[1].removeprefix('hil: trial early: ')}"



@pytest.mark.parametrize(("offset", "rate", "warned"), [(6e-3, 200.0, True), (-5.5e-3, 200.0, True),
                                                       (4.9e-3, 200.0, False), (1.2e-3, 1000.0, True), (None, 200, False)])
def test_a_lag_between_the_streams_beyond_one_imu_period_is_a_console_warning(offset, rate, warned):
    from hil.trial.live import lag_warning

    warning = lag_warning(offset, rate)
    assert (warning is not None) == warned
    if warned:
        assert f"by {offset * 1e3:.2f} ms, more than one IMU period ({1e3 / rate:.2f} ms)" in warning


def test_a_trial_refused_at_its_start_leaves_no_outputs(tmp_path, capsys):
    config = _config(tmp_path, "lab", imu={"source": "serial", "port": "/dev/ttyNOSUCH0"},
                     turntable={"source": "serial", "data_port": "/dev/ttyNOSUCH1"})
    given, made = tmp_path / "given", tmp_path / "made"
    given.mkdir()
    for out in (given, made):
        assert main(["run", str(config), "--duration", "5", *FAST, "--out", str(out)]) == 2
    assert list(given.iterdir()) == [] and not made.exists()
    capsys.readouterr()
    assert main(["replay", str(given), "--out", str(tmp_path / "replay"), *FAST[3:]]) == 2  # nothing to take
    assert "recording.mcap: cannot read" in _one_line(capsys.readouterr().err)
