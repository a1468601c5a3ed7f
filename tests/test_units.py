"""Several IMUs on one table (docs/units.md): the ``units`` block checked in one line naming ``units[i].key``, each
unit's one-unit config, and ``hil simulate`` of a units config writing each unit's trial and the trial's index."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil.cli import main
from hil.config import load_config
from hil.history.store import History
from hil.outputs.result_schema import UNITS_SCHEMA_FILE, UnitsResult, schema_text
from hil.outputs.units_index import units_exit_code
from tests.pages import clipped_columns, layout_width, needs_chromium

ROOT = Path(__file__).resolve().parent.parent
UNITS_CONFIG = ROOT / "configs" / "emulated_units.yaml"
NAMES = ["kvh-a", "kvh-b", "xsens"]


def _config(tmp_path: Path, **changes) -> Path:
    """configs/emulated_units.yaml with top-level ``changes`` (``units`` a function of the shipped list)."""
    data = yaml.safe_load(UNITS_CONFIG.read_text())
    units = changes.pop("units", None)
    if units is not None:
        data["units"] = units(data["units"])
    data.update(changes)
    path = tmp_path / "units.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_each_unit_gets_a_one_unit_config_of_its_own_imu_mounting_record_and_seed():
    cfg = load_config(UNITS_CONFIG, units=True)
    units = cfg.unit_configs()
    assert list(units) == NAMES
    assert [u.imu.protocol for u in units.values()] == ["kvh1750", "kvh1750", "xsens-mtdata2"]
    assert [u.turntable.mounting_deg for u in units.values()] == [(0, 0, 0), (90, 0, 0), (0, 180, 0)]
    assert [u.record.dut_serial for u in units.values()] == ["KVH-0001", "KVH-0002", "XS-0100"]
    assert {u.record.station for u in units.values()} == {"table-1"}  # the shared record's
    assert len({u.trial.seed for u in units.values()} | {cfg.trial.seed}) == 4
    assert all(u.turntable.motion == cfg.turntable.motion for u in units.values())
    assert all(u.units is None for u in units.values())


BAD_BLOCKS = [
    ("same_name", lambda u: [u[0], {**u[1], "name": "kvh-a"}], "units[1].name: the name 'kvh-a' is also units[0].name"),
    ("name_pattern", lambda u: [{**u[0], "name": "KVH A"}], "units[0].name: String should match pattern"),
    ("same_port", lambda u: [{**u[0], "imu": {"source": "serial", "port": "/dev/ttyUSB0"}},
                             {**u[1], "imu": {"source": "serial", "port": "/dev/ttyUSB0"}}],
     "units[1].imu.port: the port /dev/ttyUSB0 is also units[0].imu.port"),
    ("same_can_message", lambda u: [{**u[0], "imu": {"protocol": "can-dbc"}}, {**u[1], "imu": {"protocol": "can-dbc"}}],
     "units[1].imu.can: the CAN message IMU_DThetaX of configs/imu_lab_highres.dbc on udp_multicast 239.74.163.2 is "
     "also units[0].imu.can"),
    ("imu_key", lambda u: [u[0], {**u[1], "imu": {"rate_hz": 150}}], "units[1].imu.rate_hz: 150 Hz is not an integer"),
    ("rates_differ", lambda u: [u[0], {**u[1], "imu": {"rate_hz": 400}}],
     "units[1].imu.rate_hz: 400 Hz differs from units[0].imu.rate_hz (200 Hz): the table counts one sync pulse train"),
    ("unknown_key", lambda u: [u[0], {**u[1], "mounting": [0, 0, 0]}], "units[1].mounting: unknown key"),
    ("empty", lambda u: [], "units: List should have at least 1 item"),
    ("read_from_a_port", lambda u: [u[0], {**u[1], "imu": {"source": "serial", "port": "/dev/ttyUSB1"}}],
     "units[1].imu.source: serial: hil simulate emulates the devices"),
]


@pytest.mark.parametrize("units, message", [(b, m) for _, b, m in BAD_BLOCKS], ids=[i for i, _, _ in BAD_BLOCKS])
def test_a_bad_units_block_exits_2_in_one_line_naming_the_units_key(tmp_path, capsys, units, message):
    path = _config(tmp_path, units=units)
    assert main(["simulate", str(path), "--out", str(tmp_path / "out"), "--no-history"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err


def test_imu_beside_units_is_refused_naming_both(tmp_path, capsys):
    path = _config(tmp_path, imu={"protocol": "kvh1750"})
    assert main(["simulate", str(path), "--out", str(tmp_path / "out"), "--no-history"]) == 2
    assert "units: a config gives its IMUs either in units or in imu" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["ratetest", "scale-factor"]])
def test_a_one_unit_command_refuses_a_units_config_in_one_line(tmp_path, capsys, command):
    assert main([*command, str(UNITS_CONFIG), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "units: this command takes a one-unit config (imu)" in err, err
    assert not (tmp_path / "out" / "result.json").exists()


def test_the_committed_units_index_schema_is_the_models_export():
    assert UNITS_SCHEMA_FILE.read_text() == schema_text(UnitsResult), "run: python -m hil.outputs.result_schema"


@pytest.mark.parametrize("verdicts, code", [(["PASS", "PASS"], 0), (["PASS", "FAIL"], 3),
                                            (["FAIL", "ENDED EARLY", "PASS"], 1), (["INTERRUPTED", "PASS"], 1)])
def test_a_units_trial_exits_1_if_any_unit_ended_early_else_3_if_any_fails(verdicts, code):
    assert units_exit_code(verdicts) == code


@needs_chromium
def test_simulating_three_units_estimates_each_against_its_own_truth_and_files_each(tmp_path):
    """... its index page fitting the window, and --station over every unit's record."""
    path = _config(tmp_path, trial={"name": "units", "duration_s": 150, "rate_hz": 200, "seed": 11},
                   output={"figures": False},
                   units=lambda u: [{**u[0], "record": {**u[0]["record"], "station": "bench-2"}}, *u[1:]])
    out, history = tmp_path / "out", tmp_path / "h.sqlite"
    assert main(["simulate", str(path), "--out", str(out), "--history", str(history), "--station", "lab-9"]) == 0
    index = json.loads((out / "result.json").read_text())
    UnitsResult.model_validate(index, strict=True)
    assert [u["name"] for u in index["units"]] == NAMES and index["verdict"] == "PASS"
    for unit in index["units"]:
        result = json.loads((out / unit["out_dir"] / "result.json").read_text())
        bias, sigma = np.array(result["estimate"]["accel_bias_ug"]), np.array(result["estimate"]["accel_bias_sigma_ug"])
        truth = np.array(result["truth"]["accel_bias_ug"])
        assert np.all(np.abs(bias - truth) < 5 * sigma), (unit["name"], bias, truth, sigma)
        assert unit["accel_bias_ug"] == result["estimate"]["accel_bias_ug"] and unit["ended"] == "completed"
        written = {p.name for p in (out / unit["out_dir"]).iterdir()}
        assert {"series.csv", "report.html", "junit.xml", "config.yaml"} <= written
    truths = [tuple(u["truth_accel_bias_ug"]) for u in index["units"]]
    assert len(set(truths)) == 3  # each unit judged against its own errors
    suites = ET.parse(out / "junit.xml").getroot().findall("testsuite")
    assert [s.get("name") for s in suites] == [f"units/{name}" for name in NAMES]
    assert all(f"units/{name}/report.html" in (out / "report.html").read_text() for name in NAMES)
    assert sorted(row["dut_serial"] for row in History(str(history)).trials()) == ["KVH-0001", "KVH-0002", "XS-0100"]
    assert {json.loads((out / u["out_dir"] / "result.json").read_text())["record"]["station"]
            for u in index["units"]} == {"lab-9"}
    assert layout_width(out / "report.html", tmp_path) <= 1400 and clipped_columns(out / "report.html", tmp_path) == []


def test_a_units_config_yaml_alone_reproduces_its_unit_bit_for_bit(tmp_path):
    """... and a unit's noise is its own wherever it stands in ``units``; --overwrite leaves no other unit's
    outputs behind."""
    trial = {"name": "units", "duration_s": 60, "rate_hz": 200, "seed": 3}
    path = _config(tmp_path, trial=trial, output={"figures": False}, units=lambda u: u[1:])
    assert main(["simulate", str(path), "--out", str(tmp_path / "out"), "--no-history"]) in (0, 3)
    unit_dir = tmp_path / "out" / "units" / "xsens"
    first = json.loads((unit_dir / "result.json").read_text())["estimate"]
    path = _config(tmp_path, trial=trial, output={"figures": False}, units=lambda u: u[2:])
    assert main(["simulate", str(path), "--out", str(tmp_path / "out"), "--no-history", "--overwrite"]) in (0, 3)
    assert sorted(p.name for p in (tmp_path / "out" / "units").iterdir()) == ["xsens"]
    assert json.loads((unit_dir / "result.json").read_text())["estimate"] == first
    assert main(["simulate", str(unit_dir / "config.yaml"), "--out", str(tmp_path / "alone"), "--no-history"]) in (0, 3)
    again = json.loads((tmp_path / "alone" / "result.json").read_text())
    assert again["estimate"] == json.loads((unit_dir / "result.json").read_text())["estimate"]
