"""hil plan: a plan's steps run through their own commands into OUT/NN-<kind>/, plan.json listing each once,
bad steps refused before anything moves, the plan's tag in the history, resumed after a SIGKILL."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

from hil.cli import main

SWING = "configs/emulated_swing.yaml"


def write_plan(tmp_path: Path, steps: list, name: str = "smoke", config: str = SWING) -> Path:
    path = tmp_path / "plan.yaml"
    path.write_text(yaml.safe_dump({"name": name, "config": config, "steps": steps}))
    return path


def test_a_plan_runs_each_step_through_its_command_and_lists_it_once(tmp_path, capsys):
    plan = write_plan(tmp_path, [{"swing": {"trial": {"duration_s": 20}}}, {"wait": {"s": 30}},
                                 {"repeat": {"times": 2, "steps": [{"swing": {"trial": {"duration_s": 10}}}]}}])
    history = tmp_path / "history.sqlite"
    code = main(["plan", str(plan), "--out", str(tmp_path / "out"), "--speed", "max", "--no-figures",
                 "--history", str(history)])
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert [(s["index"], s["kind"], s["pass"]) for s in doc["steps"]] == [(1, "swing", None), (2, "wait", None),
                                                                          (3, "swing", 1), (4, "swing", 2)]
    assert doc["ended"] == "completed" and all(s["ended"] == "completed" for s in doc["steps"])
    for index in (1, 3, 4):
        result = json.loads((tmp_path / "out" / f"{index:02d}-swing" / "result.json").read_text())
        assert result["trial"]["duration_s"] == (20 if index == 1 else 10)
        assert result["verdict"] == doc["steps"][index - 1]["verdict"]
    assert code == {"PASS": 0, "FAIL": 3}[doc["verdict"]]
    suites = ET.parse(tmp_path / "out" / "junit.xml").getroot().findall("testsuite")
    assert [s.get("name") for s in suites] == ["01-swing", "02-wait", "03-swing", "04-swing"]
    notes = [row[0] for row in sqlite3.connect(history).execute("SELECT notes FROM trials ORDER BY id")]
    assert notes == [f"plan smoke run {doc['run']} step {name}" for name in ("01-swing", "03-swing", "04-swing")]
    assert "03-swing/report.html" in (tmp_path / "out" / "plan.html").read_text()
    assert "step 4/4 swing" in capsys.readouterr().err


@pytest.mark.parametrize("steps, named", [
    ([{"wait": {"s": 1}}, {"swing": {"trial": {"durations_s": 3}}}], "step 2: swing: trial.durations_s"),
    ([{"repeat": {"times": 2, "steps": [{"wait": {"s": 1}}, {"spin": {}}]}}], "step 2: spin: unknown step kind"),
    ([{"swing": {"imu": {"errors": {"accel_bias_ug": "big"}}}}], "step 1: swing"),
    ([{"soak": {"temperature_c": 60}}], "step 1: soak: expected {temperature_c, stable_within_c"),
    ([{"soak": {"temperature_c": 60, "stable_within_c": 1, "for_s": 60, "timeout_s": 600}}],
     "step 1: soak: the config"),
    ([{"power": "cycle", "off_s": 2}], "step 1: power: the config"),
])
def test_a_bad_step_is_refused_naming_its_index_and_key_before_anything_runs(tmp_path, capsys, steps, named):
    code = main(["plan", str(write_plan(tmp_path, steps)), "--out", str(tmp_path / "out"), "--speed", "max"])
    err = capsys.readouterr().err
    assert code == 2 and named in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_a_missing_config_is_refused(tmp_path, capsys):
    code = main(["plan", str(write_plan(tmp_path, [{"wait": {"s": 1}}], config="nowhere.yaml")), "--dry-run"])
    assert code == 2 and "config: nowhere.yaml: no such file" in capsys.readouterr().err


def test_the_dry_run_prints_the_schedule_with_its_duration(tmp_path, capsys):
    plan = write_plan(tmp_path, [{"swing": {"trial": {"duration_s": 120}}}, {"noise": {"duration_s": 60}}])
    assert main(["plan", str(plan), "--dry-run", "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "01-swing" in out and "02-noise" in out and "total 3.0 min" in out
    assert not (tmp_path / "out").exists()


def test_a_shipped_plan_is_found_by_name_from_any_directory(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["plan", "configs/plan_acceptance.yaml", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("plan acceptance: 16 steps") and "emulated_power.yaml" in out and not list(tmp_path.iterdir())


def test_a_plan_killed_in_its_third_step_resumes_without_running_the_first_two_again(tmp_path):
    plan = write_plan(tmp_path, [{"swing": {"trial": {"duration_s": 5}}}, {"wait": {"s": 1}},
                                 {"swing": {"trial": {"duration_s": 60}}}, {"wait": {"s": 1}}])  # killed at its start
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "hil.cli", "plan", str(plan), "--out", str(out), "--speed", "1", "--no-history",
            "--no-figures"]
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=Path.cwd())
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (out / "03-swing" / "recording.mcap").exists():
            time.sleep(0.05)
        assert (out / "03-swing" / "recording.mcap").exists(), "the third step never started"
        os.kill(process.pid, signal.SIGKILL)
        process.wait(30)
    finally:
        process.kill()
    before = json.loads((out / "plan.json").read_text())
    assert before["steps"][2]["ended"] is None and before["steps"][2]["started_utc"] is not None
    code = main(["plan", str(plan), "--out", str(out), "--resume", "--speed", "max", "--no-history",
                 "--no-figures"])
    after = json.loads((out / "plan.json").read_text())
    assert code in (0, 3) and after["ended"] == "completed"
    assert after["steps"][:2] == before["steps"][:2]  # kept as they were: not run again
    assert [s["index"] for s in after["steps"]] == [1, 2, 3, 4]
    assert json.loads((out / "03-swing" / "result.json").read_text())["ended"] == "completed"


def test_an_out_holding_a_plan_is_refused_without_resume(tmp_path, capsys):
    plan = write_plan(tmp_path, [{"wait": {"s": 1}}])
    assert main(["plan", str(plan), "--out", str(tmp_path / "out"), "--speed", "max"]) == 0
    assert main(["plan", str(plan), "--out", str(tmp_path / "out"), "--speed", "max"]) == 2
    assert "holds a plan's outputs" in capsys.readouterr().err


def test_a_resumed_plan_runs_a_step_that_ended_early_again_and_keeps_the_completed_ones(tmp_path):
    plan = write_plan(tmp_path, [{"wait": {"s": 1}}, {"swing": {"trial": {"duration_s": 10}}}])
    out = tmp_path / "out"
    argv = ["plan", str(plan), "--out", str(out), "--speed", "max", "--no-history", "--no-figures"]
    main(argv)
    doc = json.loads((out / "plan.json").read_text())
    first = doc["steps"][0]
    doc["steps"][1].update(ended="ended early: the table did not follow", verdict="ENDED EARLY")
    doc.update(ended="ended early at step 2 (swing)", verdict="ENDED EARLY")
    (out / "plan.json").write_text(json.dumps(doc))
    code = main([*argv, "--resume"])
    after = json.loads((out / "plan.json").read_text())
    assert after["steps"][0] == first and after["steps"][1]["ended"] == "completed"
    assert code == {"PASS": 0, "FAIL": 3}[after["verdict"]]
