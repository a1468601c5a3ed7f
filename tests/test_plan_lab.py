"""A plan in the lab form: ``hil emulate`` in its own process with the emulated supply (ports ``power``) feeding its
IMU and the emulated table, ``hil plan`` attached late with the supply as a real SCPI one and the table on its
command port. Three power-cycled swings measure the emulator's own turn-on bias spread (40 ug, its draws known
from the seed); after every way out (completed, a step failing, SIGTERM) the supply reads output off and the
table every axis Off, read back from the emulator."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import pyvisa
import yaml
from lab_form import BIAS_UG, Emulator, emulated, lab_config

from emulators.clocks import TURN_ON_STREAM, turn_on_offset_ug
from hil.cli import main

SEED = 7
SPREAD_UG = 40.0
POWER = {"voltage_v": 5.0, "current_limit_a": 1.0, "channel": 1}
pytestmark = [pytest.mark.xdist_group("lab"),
              pytest.mark.skipif(not os.environ.get("HIL_LAB_TESTS"), reason="lab form: set HIL_LAB_TESTS=1")]


def rig_config() -> dict:
    """The emulated rig: the lab-form swing, its IMU's bias spread between power-ons, the supply feeding it."""
    cfg = emulated(seed=SEED, duration_s=300.0)
    cfg["imu"]["errors"].update(turn_on_bias_ug=[SPREAD_UG] * 3, accel_noise_ug=[10] * 3)  # in-run sigma small
    cfg["environment"] = {"power": {"source": "emulator", "options": POWER}}
    return cfg


def lab_plan(tmp_path: Path, emulator: Emulator, steps: list) -> Path:
    """A plan over the running emulator's ports: the table commanded, the supply a SCPI one at ports ``power``."""
    lab = lab_config(rig_config(), emulator.ports, tmp_path, commanded=True)
    cfg = yaml.safe_load(lab.read_text())
    cfg["environment"] = {"power": {"controller": "scpi", "port": emulator.ports["power"], "options": POWER}}
    lab.write_text(yaml.safe_dump(cfg))
    path = tmp_path / "plan.yaml"
    path.write_text(yaml.safe_dump({"name": "lab", "config": str(lab), "steps": steps}))
    return path


def supply_output(emulator: Emulator) -> tuple[str, float]:
    """``OUTP?`` and ``MEAS:CURR?`` as a third-party VISA client reads them."""
    client = pyvisa.ResourceManager("@py").open_resource(emulator.ports["power"], read_termination="\n",
                                                        write_termination="\n")
    try:
        return client.query("OUTP?"), float(client.query("MEAS:CURR?"))
    finally:
        client.close()


def table_modes(emulator: Emulator) -> str:
    """The table's modes as the emulator reports them when it stops."""
    emulator.stop()
    return json.loads(emulator.stats_file.read_text())["table_modes"]


def test_three_power_cycled_swings_hold_the_emulated_turn_on_spread_and_the_rig_ends_safe(tmp_path, capsys):
    steps = [{"repeat": {"times": 3, "steps": [{"power": "cycle", "off_s": 1},
                                               {"swing": {"trial": {"duration_s": 12}}}]}}]
    with Emulator(tmp_path, rig_config()) as emulator:
        time.sleep(max(0.0, 1.5 - (time.monotonic() - emulator.started)))  # attached late
        code = main(["plan", str(lab_plan(tmp_path, emulator, steps)), "--out", str(tmp_path / "out"),
                     "--no-history", "--no-figures"])
        supply = supply_output(emulator)
        modes = table_modes(emulator)
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    figures = doc["units"]["imu"]
    assert code in (0, 3) and doc["ended"] == "completed" and figures["power_ons"] == 3
    drawn = np.array([turn_on_offset_ug([SPREAD_UG] * 3, (SEED, TURN_ON_STREAM, n)) for n in (1, 2, 3)])
    error = np.array(figures["biases_ug"]) - (np.array(BIAS_UG) + drawn)  # each swing saw its power-on's bias
    assert np.all(np.abs(error) < 5 * np.array(figures["in_run_sigma_ug"]) + 2.0), (error, figures)
    for axis in range(3):
        low, high = figures["turn_on_repeatability_ci_ug"][axis]
        assert low < SPREAD_UG < high, figures
    assert supply == ("0", 0.0) and modes == "Off,Off,Off"
    out = capsys.readouterr().out
    assert "turntable: every axis Off (read back)" in out and "power supply: output off (read back)" in out


def test_a_failing_step_leaves_the_supply_off_and_the_table_off(tmp_path, capsys):
    """The emulated table swings from its start; the plan's swing finds the unit unpowered and stops the plan."""
    with Emulator(tmp_path, rig_config()) as emulator:
        code = main(["plan", str(lab_plan(tmp_path, emulator, [{"power": "off"}, {"swing": {}}])),
                     "--out", str(tmp_path / "out"), "--no-history", "--no-figures"])
        supply = supply_output(emulator)
        modes = table_modes(emulator)
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert code == 1 and doc["steps"][1]["ended"].startswith("ended early: the unit is not powered")
    assert supply == ("0", 0.0) and modes == "Off,Off,Off"
    assert "turntable: every axis Off (read back)" in capsys.readouterr().out


def test_a_plan_ended_by_sigterm_leaves_the_supply_off_and_the_table_off(tmp_path):
    with Emulator(tmp_path, rig_config()) as emulator:
        plan = lab_plan(tmp_path, emulator, [{"power": "on"}, {"swing": {"trial": {"duration_s": 200}}}])
        out = tmp_path / "out"
        process = subprocess.Popen([sys.executable, "-m", "hil.cli", "plan", str(plan), "--out", str(out),
                                    "--no-history", "--no-figures"], stdout=subprocess.PIPE,
                                   stderr=subprocess.DEVNULL, text=True)
        try:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not (out / "02-swing" / "recording.mcap").exists():
                time.sleep(0.05)
            time.sleep(2.0)  # the table swinging under the trial
            os.kill(process.pid, signal.SIGTERM)
            stdout, _ = process.communicate(timeout=60)
        finally:
            process.kill()
        supply = supply_output(emulator)
        modes = table_modes(emulator)
    assert process.returncode == 1 and json.loads((out / "plan.json").read_text())["verdict"] == "INTERRUPTED"
    assert supply == ("0", 0.0) and modes == "Off,Off,Off"
    assert "turntable: every axis Off (read back)" in stdout and "power supply: output off (read back)" in stdout
