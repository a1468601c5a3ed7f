"""The SCPI power supply in a plan: the emulated supply seen by a third-party VISA client, every write read back,
power-cycled swings with a new turn-on bias each and their repeatability, and the supply off on every way out."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import pyvisa
import yaml

from drivers.scpi_supply import ScpiSupply, SupplyError, SupplySettings
from emulators.scpi_supply import EmulatedSupply, SupplyState
from hil.cli import main
from pages import clipped_columns, layout_width, needs_chromium

ROOT = Path(__file__).resolve().parent.parent
POWER_CONFIG = str(ROOT / "configs" / "emulated_power.yaml")


def write_plan(tmp_path: Path, steps: list) -> Path:
    path = tmp_path / "plan.yaml"
    path.write_text(yaml.safe_dump({"name": "power", "config": POWER_CONFIG, "steps": steps}))
    return path


@pytest.fixture
def supply():
    server = EmulatedSupply(SupplyState(load_a=0.35))
    yield server
    server.close()


def test_a_third_party_visa_client_sees_the_emulated_supply_power_the_unit(supply):
    client = pyvisa.ResourceManager("@py").open_resource(supply.resource, read_termination="\n",
                                                        write_termination="\n")
    assert client.query("*IDN?").startswith("turntable-hil,")
    assert client.query("OUTP?") == "0" and float(client.query("MEAS:CURR?")) == 0.0
    client.write("VOLT 5")
    client.write("OUTP ON")
    assert client.query("OUTP?") == "1" and float(client.query("MEAS:CURR?")) == pytest.approx(0.35)
    client.write("OUTP OFF")
    client.write("OUTP ON")
    assert client.query("OUTP?") == "1" and supply.state.power_ons == 2  # the query waits for the writes before it
    client.close()


def test_a_setting_the_supply_does_not_confirm_is_refused_naming_the_command(supply):
    with pytest.raises(SupplyError, match=r"INST:NSEL 7: read back '1'"):
        ScpiSupply(supply.resource, SupplySettings(5.0, 1.0, channel=7)).open()
    driver = ScpiSupply(supply.resource, SupplySettings(5.0, 0.2, channel=2)).open()
    assert supply.state.voltage[2] == 5.0 and supply.state.current[2] == 0.2
    driver.close()


@needs_chromium
def test_power_cycled_swings_give_a_turn_on_repeatability_whose_interval_holds_the_truth(tmp_path, capsys):
    steps = [{"repeat": {"times": 3, "steps": [{"power": "cycle", "off_s": 2},
                                               {"swing": {"trial": {"duration_s": 40}}}]}}]
    code = main(["plan", str(write_plan(tmp_path, steps)), "--out", str(tmp_path / "out"), "--speed", "max",
                 "--no-history", "--no-figures"])
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    figures = doc["units"]["imu"]
    assert code in (0, 3) and figures["power_ons"] == 3
    truths = [json.loads((tmp_path / "out" / f"{i:02d}-swing" / "result.json").read_text())["truth"]["accel_bias_ug"]
              for i in (2, 4, 6)]
    assert len({tuple(t) for t in truths}) == 3  # a new turn-on bias at each power-on
    for axis in range(3):
        low, high = figures["turn_on_repeatability_ci_ug"][axis]
        assert low < figures["truth_turn_on_bias_ug"][axis] == 40 < high
        assert figures["in_run_sigma_ug"][axis] < figures["turn_on_repeatability_ug"][axis]
    assert doc["steps"][1]["power"] == {"output_on": True, "voltage_v": 5.0, "current_a": 0.35}
    assert "power supply: output off (read back)" in capsys.readouterr().out
    page = tmp_path / "out" / "plan.html"
    assert "turn-on-to-turn-on" in page.read_text()
    assert layout_width(page, tmp_path) <= 1400 and clipped_columns(page, tmp_path) == []


def test_a_trial_step_with_the_power_off_ends_early_and_stops_the_plan_with_the_supply_off(tmp_path, capsys):
    steps = [{"power": "on"}, {"power": "off"}, {"swing": {"trial": {"duration_s": 10}}}, {"wait": {"s": 1}}]
    code = main(["plan", str(write_plan(tmp_path, steps)), "--out", str(tmp_path / "out"), "--speed", "max",
                 "--no-history"])
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert code == 1 and doc["verdict"] == "ENDED EARLY"
    assert doc["steps"][2]["ended"] == "ended early: the unit is not powered (the power supply's output is off)"
    assert doc["steps"][3]["ended"] is None  # on_failure: stop
    assert "power supply: output off (read back)" in capsys.readouterr().out


def test_a_plan_ended_by_sigterm_turns_the_supply_off_and_reads_it_back(tmp_path):
    steps = [{"power": "on"}, {"swing": {"trial": {"duration_s": 600}}}, {"wait": {"s": 1}}]
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "hil.cli", "plan", str(write_plan(tmp_path, steps)), "--out", str(out),
            "--speed", "1", "--no-history", "--no-figures"]
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (out / "02-swing" / "recording.mcap").exists():
            time.sleep(0.05)
        time.sleep(1.0)
        os.kill(process.pid, signal.SIGTERM)
        stdout, _ = process.communicate(timeout=60)
    finally:
        process.kill()
    doc = json.loads((out / "plan.json").read_text())
    assert process.returncode == 1 and doc["verdict"] == "INTERRUPTED"
    assert doc["steps"][2]["ended"] is None
    assert "power supply: output off (read back), 0 V, 0 A" in stdout


def test_a_supply_that_stops_answering_ends_the_step_early_naming_it_without_a_traceback(tmp_path, capsys,
                                                                                         monkeypatch):
    def lost(self):
        raise SupplyError(f"power supply {self.resource}: MEAS:CURR?: timeout")

    monkeypatch.setattr(ScpiSupply, "read", lost)
    steps = [{"power": "on"}, {"swing": {"trial": {"duration_s": 10}}}]
    code = main(["plan", str(write_plan(tmp_path, steps)), "--out", str(tmp_path / "out"), "--speed", "max",
                 "--no-history"])
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert code == 1 and doc["steps"][1]["ended"].endswith("MEAS:CURR?: timeout")
    captured = capsys.readouterr()
    assert "power supply: not confirmed" in captured.out and "Traceback" not in captured.err


LOGGED_SUPPLY = '''
from drivers.scpi_supply import Reading


class LoggedSupply:
    """A supply that writes what it is told to the file its resource names."""

    def __init__(self, resource, settings):
        self.resource, self.settings, self.on = resource, settings, False

    def say(self, line):
        with open(self.resource, "a") as log:
            log.write(line + "\\n")

    def open(self):
        self.say(f"open {self.settings.voltage_v:g} V {self.settings.current_limit_a:g} A")
        return self

    def output(self, on):
        self.on = on
        self.say("on" if on else "off")

    def read(self):
        return Reading(self.on, self.settings.voltage_v if self.on else 0.0, 0.2 if self.on else 0.0)

    def close(self):
        self.say("close")
'''


def test_a_supply_plug_in_of_the_entry_point_group_runs_the_power_steps_and_ends_off(tmp_path, monkeypatch, capsys):
    site = tmp_path / "site"
    info = site / "bench_supply-0.1.dist-info"
    info.mkdir(parents=True)
    (site / "logged_supply.py").write_text(LOGGED_SUPPLY)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: bench-supply\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[turntable_hil.power_supplies]\nlogged = logged_supply:LoggedSupply\n")
    monkeypatch.syspath_prepend(str(site))
    log = tmp_path / "supply.log"
    cfg = yaml.safe_load(Path(POWER_CONFIG).read_text())
    cfg["environment"]["power"] = {"controller": "logged", "port": str(log), "options": {"voltage_v": 12}}
    (tmp_path / "lab.yaml").write_text(yaml.safe_dump(cfg))
    plan = tmp_path / "plan.yaml"
    plan.write_text(yaml.safe_dump({"name": "plug-in", "config": str(tmp_path / "lab.yaml"),
                                    "steps": [{"power": "on"}, {"power": "cycle", "off_s": 1}]}))
    code = main(["plan", str(plan), "--out", str(tmp_path / "out"), "--speed", "max", "--no-history"])
    assert code == 0 and log.read_text().splitlines() == ["open 12 V 1 A", "on", "off", "on", "off", "close"]
    assert "power supply: output off (read back), 0 V, 0 A" in capsys.readouterr().out
