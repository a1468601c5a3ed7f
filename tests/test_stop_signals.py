"""Every way out of a trial that commands the table is safe: SIGTERM, SIGINT and SIGHUP mid-trial."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from hil.cli import main
from tests.helpers import processed

ROOT = Path(__file__).resolve().parents[1]


# per controller: the trial it commands, its modes after Off, the emulator's log line of the Off
CONTROLLERS = {
    "acutrol": ("emulated_swing.yaml", "Off,Off,Off", "acutrol: :Mode:Off 3;:Mode:Off 2;:Mode:Off 1 -> OK"),
    "aerosmith": ("rate_table_aerosmith.yaml", "Off", "aerosmith: STO -> OK"),
}


def _commanded_config(tmp_path: Path, controller: str = "acutrol") -> Path:
    cfg = yaml.safe_load((ROOT / "configs" / CONTROLLERS[controller][0]).read_text())
    cfg["turntable"]["command_port"] = "emulator"
    # a 16-bit packet counter: a host stall of the loaded test machine is never taken for counter wraps
    # (the KVH's 7-bit counter wraps every 160 ms at --speed 4; see docs/harness.md)
    cfg["imu"]["protocol"] = "xsens-mtdata2"
    path = tmp_path / "commanded.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _wait_for_data(proc: subprocess.Popen, recording: Path) -> None:
    deadline = time.monotonic() + 60
    while not (recording.exists() and recording.stat().st_size > 100_000):
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, "no data recorded within 60 s"
        time.sleep(0.1)


@pytest.mark.parametrize(("sig", "controller"), [  # each signal, each controller; the double Ctrl-C with both
    (signal.SIGTERM, "acutrol"), (signal.SIGINT, "acutrol"), (signal.SIGINT, "aerosmith"),
    (signal.SIGHUP, "aerosmith")])
def test_a_signal_mid_trial_turns_the_table_off_and_keeps_replayable_outputs(tmp_path, sig, controller):
    out = tmp_path / "out"
    _, modes, off_line = CONTROLLERS[controller]
    proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "run", str(_commanded_config(tmp_path, controller)),
                             "--duration", "300", "--speed", "4", "--quiet", "--viewer", "none", "--no-figures",
                             "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_data(proc, out / "recording.mcap")
        proc.send_signal(sig)
        if sig == signal.SIGINT:  # an impatient second Ctrl-C during the shutdown: Off is still sent first
            time.sleep(0.3)
            proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 1, err
    result = json.loads((out / "result.json").read_text())
    assert result["ended"] == f"interrupted: {sig.name}"
    assert 0 < result["trial"]["duration_s"] < 300
    assert (out / "report.html").exists() and "trial_completed" in (out / "junit.xml").read_text()
    emulator = json.loads((out / "emulator.json").read_text())
    assert emulator["table_modes_off"] == 1 and emulator["table_modes"] == modes
    assert off_line in (out / "emulator.log").read_text()
    assert "could not confirm" not in err
    # the recording holds everything the trial processed and says how it ended
    assert main(["replay", str(out), "--out", str(tmp_path / "replay"), "--viewer", "none", "--no-figures"]) == 1
    assert processed(tmp_path / "replay") == processed(out)
