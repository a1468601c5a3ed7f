"""A third-party controller: a tiny package, installed with pip into a temporary virtual environment, that
registers a controller and its emulated table through the entry-point group alone, drives an emulated trial."""

from __future__ import annotations

import json
import subprocess
import sys
import sysconfig
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]

# The plug-in: a made-up line dialect ("MOVE <gimbal> <deg>", "SPIN ...", "SWING ...", "MODE <gimbal> <mode>",
# "LOCKS? <gimbal>", "STOP", "MODES?"), one reply line each: a value, "ok" or "no <why>".
PLUGIN = '''
from pydantic import BaseModel, ConfigDict

from drivers.table_controller import TableController, TableError
from emulators.servo import Refused
from hil.samples import GIMBAL_AXES
from hil.vocabulary import TableMode


class TinyOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    greeting: str = "hello"


class TinyController(TableController):
    name = "tiny"
    Options = TinyOptions
    emulated = "tiny_table:TinyTable"

    def ask(self, line):
        port = self._io(line)
        port.write(line.encode() + b"\\n")
        reply = port.read_until(b"\\n").decode().strip()
        if not reply or reply.startswith("no"):
            raise TableError(f"tiny table refused {line}: {reply or 'no reply'}")
        return reply

    def identify(self):
        return self.ask(self.options.greeting.upper())

    def read_position(self, gimbal):
        return float(self.ask(f"WHERE {gimbal}"))

    def _load_limits(self, gimbal, low, high, rate, accel):
        self.ask(f"LIMIT {gimbal} {rate} {accel}")

    def _interlocks(self, gimbal):
        return self.ask(f"LOCKS? {gimbal}")

    def _close_interlocks(self, gimbal):
        self.ask(f"CLOSE {gimbal}")

    def _mode(self, gimbal, mode):
        self.ask(f"MODE {gimbal} {mode}")

    def _position(self, gimbal, deg):
        self.ask(f"MOVE {gimbal} {deg}")

    def _rate(self, gimbal, dps):
        self.ask(f"SPIN {gimbal} {dps}")

    def _oscillator(self, gimbal, amplitude, frequency, phase):
        self.ask(f"SWING {gimbal} {amplitude} {frequency} {phase}")

    def _off(self):
        self.ask("STOP")
        return dict(zip(GIMBAL_AXES, self.ask("MODES?").split()))


class TinyTable:
    def __init__(self, servo, options, log=False):
        self.servo, self.received, self.log, self.offs, self._buf = servo, {}, [], 0, b""

    def reset(self):
        self._buf = b""

    def modes(self):
        return " ".join(self.servo.mode(k) for k in range(3))

    def feed(self, data):
        self._buf += data
        *lines, self._buf = self._buf.split(b"\\n")
        return b"".join(self.answer(line.decode().strip()) + b"\\n" for line in lines if line.strip())

    def answer(self, line):
        word, *args = line.split()
        self.received[word] = self.received.get(word, 0) + 1
        try:
            reply = self.run(word, args)
        except Refused as exc:
            reply = f"no {exc}"
        self.log.append((line, int(reply.startswith("no"))))
        return reply.encode()

    def run(self, word, args):
        s = self.servo
        axes = [GIMBAL_AXES.index(args[0])] if args else []
        if word == "HELLO":
            return "tiny table"
        if word == "LIMIT":
            for mode in TableMode:
                s.set_limit(mode, axes, "rate", float(args[1]))
                s.set_limit(mode, axes, "accel", float(args[2]))
        elif word == "LOCKS?":
            return s.interlock_state(axes[0])
        elif word == "MODE":
            s.set_mode(axes, args[1])
        elif word in ("MOVE", "SPIN", "SWING"):
            kind = {"MOVE": "position", "SPIN": "rate", "SWING": "oscillator"}[word]
            s.demand(axes, kind, tuple(float(a) for a in args[1:]))
        elif word == "STOP":
            s.set_mode([0, 1, 2], TableMode.OFF)
            self.offs += 1
        elif word == "MODES?":
            return self.modes()
        elif word == "WHERE":
            return f"{s.reading(axes[0])[0]:.6f}"
        else:
            return f"no such command {word}"
        return "ok"
'''


def test_a_controller_from_an_installed_package_drives_an_emulated_trial(tmp_path):
    package = tmp_path / "tiny"
    package.mkdir()
    (package / "tiny_table.py").write_text(PLUGIN)
    (package / "pyproject.toml").write_text(
        '[build-system]\nrequires = ["setuptools"]\nbuild-backend = "setuptools.build_meta"\n\n'
        '[project]\nname = "tiny-table"\nversion = "0.1"\n\n'
        '[project.entry-points."turntable_hil.table_controllers"]\ntiny = "tiny_table:TinyController"\n\n'
        '[tool.setuptools]\npy-modules = ["tiny_table"]\n')
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          check=True, capture_output=True, text=True).stdout.strip()
    # the project and its dependencies, as this environment has them; the plug-in is installed, not pointed at
    Path(site, "project.pth").write_text(f"{ROOT}\n{sysconfig.get_paths()['purelib']}\n")
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index",
                    str(package)], check=True)

    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["turntable"].update(command_port="emulator", controller="tiny", controller_options={"greeting": "hello"})
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    run = subprocess.run([str(python), "-m", "hil.cli", "run", str(config), "--duration", "12", "--speed", "max",
                          "--quiet", "--viewer", "none", "--no-figures", "--out", str(out)],
                         capture_output=True, text=True, cwd=tmp_path, check=False)
    assert run.returncode in (0, 3), run.stderr  # 12 s: completed, perhaps short of a limit
    assert json.loads((out / "result.json").read_text())["ended"] == "completed"
    stats = json.loads((out / "emulator.json").read_text())
    assert stats["table_modes"] == "off off off" and stats["table_modes_off"] == 1
    lines = [line for line, code in stats["table_log"] if not code]
    assert "SWING inner 13.0 0.125 0.0" in lines and lines[-2:] == ["STOP", "MODES?"]

    cfg["turntable"]["controller_options"] = {"greting": "hi"}
    config.write_text(yaml.safe_dump(cfg))
    bad = subprocess.run([str(python), "-m", "hil.cli", "run", str(config), "--out", str(tmp_path / "bad"),
                          "--viewer", "none", "--quiet"], capture_output=True, text=True, cwd=tmp_path, check=False)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert "turntable.controller_options: greting: unknown key (the tiny options)" in bad.stderr
