"""Ctrl-C at any moment of a command's start-up is one line and exit 130, never a traceback; once the trial runs,
it ends the trial as interrupted (exit 1). The signal is sent at delays after the console script has imported
the package hil (the interpreter's own start, before any of hil's code runs, is out of its reach), seen from the
interpreter's import log on stderr."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
HIL = Path(sys.executable).parent / "hil"
DELAYS = (0.0, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0)  # s after the package hil is imported
TRIAL_LINES = ("hil: SIGINT: ending the trial (turntable off, outputs kept)", "hil: trial interrupted: SIGINT")

COMMANDS = {
    "run": ["run", "configs/emulated_swing.yaml", "--duration", "600", "--speed", "max", "--viewer", "none",
            "--quiet", "--no-figures", "--no-history"],
    "simulate": ["simulate", "{long_swing}", "--no-figures", "--no-history"],  # 2 h: seconds to simulate
    "noise": ["noise", "configs/noise_static.yaml", "--no-figures", "--no-history"],  # 8 h: never done by then
}


def _interrupted(args: list[str], delay: float, out: Path) -> tuple[int, list[str]]:
    """Exit code and stderr (the import log left out) of ``hil ARGS --out OUT`` sent SIGINT ``delay`` s after the
    console script imported the package hil."""
    env = {**os.environ, "PYTHONPROFILEIMPORTTIME": "1"}
    proc = subprocess.Popen([str(HIL), *args, "--out", str(out)], cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        for line in proc.stderr:
            lines.append(line)
            if line.startswith("import time:") and line.split("|")[-1].strip() == "hil":
                break
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        rest = proc.stderr.read()
        proc.wait(timeout=120)
    finally:
        proc.kill()
        proc.stderr.close()
    err = [line for line in "".join(lines).splitlines() + rest.splitlines() if not line.startswith("import time:")]
    return proc.returncode, err


def _long_swing(directory: Path) -> Path:
    """The default trial's swing made 2 h long: still simulating a second after its start, however fast."""
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["trial"]["duration_s"] = 7200
    path = directory / "long_swing.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_ctrl_c_at_any_moment_of_start_up_is_one_line_and_exit_130(tmp_path, command):
    args = [arg.format(long_swing=_long_swing(tmp_path)) for arg in COMMANDS[command]]
    for delay in DELAYS:
        code, err = _interrupted(args, delay, tmp_path / f"out-{delay}")
        assert not any("Traceback" in line for line in err), (delay, "\n".join(err))
        if code == 130:
            assert err == ["hil: interrupted"], (delay, err)
        else:  # the trial was running: it ended as interrupted
            assert command == "run" and code == 1 and err[0] == TRIAL_LINES[0] and err[-1] == TRIAL_LINES[1], \
                (delay, code, err)


LOSES_ONE = """
import signal, sys, time
import hil
signal.signal(signal.SIGINT, hil.interrupted_at_start)  # as the console script starts
from hil import cli

def loses_the_first(args):
    try:
        signal.raise_signal(signal.SIGINT)
    except KeyboardInterrupt:
        print("lost", file=sys.stderr, flush=True)  # as the import system's module-lock callbacks lose one
    for _ in range(1000):
        time.sleep(0.01)
    return 0

cli.COMMANDS["simulate"] = loses_the_first
sys.exit(cli.main(["simulate", "any.yaml"]))
"""


def test_a_ctrl_c_lost_on_the_way_is_sent_again_until_the_command_ends_with_130():
    proc = subprocess.run([sys.executable, "-c", LOSES_ONE], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert (proc.returncode, proc.stderr.splitlines()) == (130, ["lost", "hil: interrupted"])
