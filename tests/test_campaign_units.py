"""Campaigns of a units config (docs/units.md): a run of the config is a row per unit, each unit's row what `hil
simulate` of the run's units config gives that unit; a sweep of one unit's key; the unit keys a SPEC refuses;
resuming per unit; the summary per sweep point and unit; a noise and a calibration campaign of units."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from hil.campaign.runner import resumed_rows, run_campaign
from hil.campaign.runs import failed_row, flatten
from hil.campaign.spec import SpecError, check_key, load_campaign, run_seeds
from hil.campaign.table import read_runs, write_runs

ROOT = Path(__file__).resolve().parent.parent
UNITS = ROOT / "configs" / "emulated_units.yaml"
NAMES = ["kvh-a", "kvh-b", "xsens"]
SERIALS = {"kvh-a": "KVH-0001", "kvh-b": "KVH-0002", "xsens": "XS-0100"}
KEY = "units.1.imu.errors.accel_bias_ug"  # kvh-b's
BIASES = [[-120, 40, 310], [0, 0, 500]]
SEED = 7


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def _units_config(tmp: Path, duration_s: float = 30.0) -> Path:
    config = yaml.safe_load(UNITS.read_text())
    config["trial"]["duration_s"] = duration_s
    path = tmp / "units.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def _spec(tmp: Path, base: Path, sweep: dict, **keys) -> Path:
    path = tmp / "spec.yaml"
    path.write_text(yaml.safe_dump({"base": str(base), "runs": 2, "seed": SEED, "sweep": sweep, **keys}))
    return path


@pytest.fixture(scope="module")
def swing(tmp_path_factory):
    """A swing campaign of the three units, 30 s: kvh-b's bias swept over two points, two runs each."""
    tmp = tmp_path_factory.mktemp("units-campaign")
    base = _units_config(tmp)
    console = io.StringIO()
    with contextlib.redirect_stdout(console):
        code = run_campaign(_spec(tmp, base, {KEY: BIASES}), tmp / "o", workers=2)
    return tmp, base, code, read_runs(tmp / "o"), console.getvalue()


def _simulated(base: Path, point: int, seed: int) -> dict[str, dict]:
    """Each unit's result of `hil simulate` of a run's units config (hil/commands/trials.py, its units path), the
    config made here from the base: kvh-b's bias and trial.seed set."""
    from hil.config import parse_config
    from hil.trial.offline import run_simulation
    from hil.trial.units import run_units
    from hil.trial.viewer_feed import ViewerOptions

    config = yaml.safe_load(base.read_text())
    config["units"][1]["imu"]["errors"]["accel_bias_ug"] = BIASES[point]
    config["trial"]["seed"] = seed
    fixture = run_units(parse_config(config, "run", units=True), base.parent, lambda unit, text, out: run_simulation(
        unit, text, out, ViewerOptions())[0])
    return {name: outcome.result for name, outcome in fixture.units.items()}


def test_each_units_row_is_what_hil_simulate_of_the_runs_units_config_gives_that_unit(swing):
    _, base, code, rows, _ = swing
    assert code == 0 and len(rows) == 2 * 2 * 3 and all(row["error"] is None for row in rows)
    seeds = run_seeds(SEED, 2)
    assert [(row["point"], row["run"], row["unit"], row["seed"]) for row in rows] == [
        (p, r, name, seeds[r]) for p in range(2) for r in range(2) for name in NAMES]
    assert [row["id"] for row in rows[:3]] == ["p000-r0000-kvh-a", "p000-r0000-kvh-b", "p000-r0000-xsens"]
    simulated = {(p, r): _simulated(base, p, seeds[r]) for p in range(2) for r in range(2)}
    for row in rows:
        expected = flatten(simulated[(row["point"], row["run"])][row["unit"]])
        compared = {k: v for k, v in expected.items() if not k.startswith("record.")}
        assert {k: row[k] for k in compared} == compared, row["id"]
        assert row["record.dut_serial"] == SERIALS[row["unit"]]
    assert rows[0]["trial.name"] == "emulated-units.kvh-a" and rows[0]["estimate.accel_bias_ug.0"] is not None


def test_a_sweep_of_one_units_key_changes_that_units_truth_only(swing):
    rows = swing[3]
    for row in rows:
        truth = [row[f"truth.accel_bias_ug.{i}"] for i in range(3)]
        assert (truth == BIASES[row["point"]]) == (row["unit"] == "kvh-b")
        assert [row[f"sweep.{KEY}.{i}"] for i in range(3)] == BIASES[row["point"]]
    by = {(row["point"], row["run"], row["unit"]): row for row in rows}
    unswept = ("id", "point", "record.config_sha256") + tuple(f"sweep.{KEY}.{i}" for i in range(3))
    for r in range(2):
        for name in ("kvh-a", "xsens"):  # the same noise at both points (common random numbers): the same row
            first, second = ({k: v for k, v in by[(p, r, name)].items() if k not in unswept} for p in range(2))
            assert first == second
        errors = [[by[(p, r, "kvh-b")][f"estimate.accel_bias_ug.{i}"] - BIASES[p][i] for i in range(3)]
                  for p in range(2)]
        assert errors[0] == pytest.approx(errors[1], abs=1e-6)  # kvh-b's own noise too: only its truth moved


def test_the_summary_and_the_page_have_an_entry_per_sweep_point_and_unit(swing):
    tmp, console = swing[0], swing[4]
    summary = json.loads((tmp / "o" / "summary.json").read_text())
    assert summary["runs"] == 12 and summary["failed"] == 0
    assert [(p["point"], p["unit"]) for p in summary["points"]] == [(p, n) for p in range(2) for n in NAMES]
    assert all(list(p)[:3] == ["point", "unit", "values"] and p["runs"] == 2 for p in summary["points"])
    assert summary["points"][1]["values"] == {KEY: BIASES[0]}
    assert f"  unit=kvh-b, {KEY}=[0, 0, 500]: std(error)/sigma " in console
    page = (tmp / "o" / "campaign.html").read_text()
    assert page.count("<td rowspan=3>unit=xsens, units.1.<wbr>imu.") == 2


def test_resume_keeps_each_units_done_run_and_refuses_a_row_of_another_unit(tmp_path):
    campaign = load_campaign(_spec(tmp_path, _units_config(tmp_path), {KEY: BIASES[:1]}))
    tasks = {task.id: task for task in campaign.tasks}
    assert len(tasks) == 6 and tasks["p000-r0001-xsens"].unit == "xsens"
    done = {**failed_row(tasks["p000-r0000-kvh-a"], "x"), "error": None}
    write_runs(tmp_path, [done, failed_row(tasks["p000-r0000-kvh-b"], "worker lost")])
    assert [row["id"] for row in resumed_rows(campaign, tmp_path)] == ["p000-r0000-kvh-a"]
    write_runs(tmp_path, [{**done, "unit": "kvh-b"}])
    with pytest.raises(SpecError, match="run p000-r0000-kvh-a is not one of"):
        resumed_rows(campaign, tmp_path)


def test_a_units_task_is_the_units_one_unit_config_of_the_run():
    campaign = load_campaign(ROOT / "configs" / "campaign_units.yaml")
    assert campaign.spec.base == "emulated_units.yaml" and len(campaign.tasks) == 3 * len(campaign.points) * 4
    task = campaign.tasks[1]
    assert (task.id, task.unit, task.seed) == ("p000-r0000-kvh-b", "kvh-b", run_seeds(campaign.spec.seed, 4)[0])
    assert "units" not in task.config and task.config["turntable"]["mounting_deg"] == [90, 0, 0]
    assert task.config["trial"]["name"] == "emulated-units.kvh-b" and task.config["trial"]["seed"] != task.seed
    assert task.config["record"] == {"station": "table-1", "dut_part": "KVH 1750", "dut_serial": "KVH-0002"}


def test_unit_keys_are_checked_by_model_and_index():
    check_key(KEY)
    check_key("units.0.mounting_deg")
    check_key("units.2")
    with pytest.raises(SpecError, match=r"^sweep.units.x.imu: units.x: expected an index of the list units"):
        check_key("units.x.imu")
    with pytest.raises(SpecError, match=r"^sweep.units.1.imux: unknown key 'units.1.imux' of the trial config$"):
        check_key("units.1.imux")


@pytest.mark.parametrize(("base", "key", "said"), [
    (UNITS, "units.3.imu.errors.accel_bias_ug", "units.3: index out of range: the base config has 3 units (0 to 2)"),
    (UNITS, "units.x.imu.errors.accel_bias_ug", "units.x: expected an index of the list units (0, 1, ...)"),
    (ROOT / "configs" / "liu2019_sim.yaml", "units.0.imu.errors.accel_bias_ug",
     "units.0: the base config has no units to index")])
def test_a_bad_unit_key_exits_2_with_one_line_naming_it(tmp_path, base, key, said):
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "campaign", str(_spec(tmp_path, base, {key: [[1, 2, 3]]})),
                           "--out", "o"], check=False, cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env=_env())
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert f"spec.yaml: sweep.{key}: {said}" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_a_noise_campaign_of_units_analyses_each_unit_with_its_own_truth(tmp_path, capsys):
    config = yaml.safe_load((ROOT / "configs" / "noise_static.yaml").read_text())
    imu = config.pop("imu")
    quiet = {**imu, "errors": {**imu["errors"], "accel_noise_ug": [100, 100, 100]}}
    config.update(units=[{"name": "a", "imu": imu}, {"name": "b", "mounting_deg": [0, 180, 0], "imu": quiet}])
    (tmp_path / "units.yaml").write_text(yaml.safe_dump(config))
    spec = _spec(tmp_path, tmp_path / "units.yaml", {"trial.duration_s": [120.0]}, kind="noise")
    assert run_campaign(spec, tmp_path / "o", workers=2) == 0
    rows = read_runs(tmp_path / "o")
    assert [(row["run"], row["unit"], row["samples"]) for row in rows] == [(r, u, 12000) for r in range(2) for u in "ab"]
    vrw = {row["unit"]: row["truth.accel.vrw_m_per_s_per_sqrt_h.0"] for row in rows}
    assert vrw["a"] == pytest.approx(4.20129 * vrw["b"])
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert [(p["unit"], p["done"]) for p in summary["points"]] == [("a", 2), ("b", 2)]
    assert "unit=b, trial.duration_s=120.0: 2 runs, coverage" in capsys.readouterr().out


@pytest.mark.slow
def test_a_calibration_campaign_of_units_calibrates_each_unit_through_its_mounting(tmp_path, capsys):
    spec = _spec(tmp_path, ROOT / "configs" / "calibration_units.yaml", {
        "calibration.positions": [6], "calibration.dwell_s": [1], "calibration.plateau_s": [2]}, kind="calibration")
    assert run_campaign(spec, tmp_path / "o", workers=2) == 0
    rows = read_runs(tmp_path / "o")
    assert [row["unit"] for row in rows] == NAMES * 2 and {row["ended"] for row in rows} == {"completed"}
    for row in rows:  # each unit's own bias, as its triad sees it
        truth = {"kvh-a": 60.0, "kvh-b": -120.0, "xsens": 200.0}[row["unit"]]
        assert row["term.accel.bias_ug.0.truth"] == pytest.approx(truth)
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert [(p["unit"], p["done"]) for p in summary["points"]] == [(name, 2) for name in NAMES]
    assert "Calibration consistency per sweep point" in (tmp_path / "o" / "campaign.html").read_text()
    assert "  unit=xsens, calibration.dwell_s=1, calibration.plateau_s=2, calibration.positions=6: 2 runs" in (
        capsys.readouterr().out)
