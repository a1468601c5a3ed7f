"""The shipped acceptance plan (configs/plan_acceptance.yaml) at --speed max: killed with SIGKILL in its third step
and resumed, it completes without running steps one and two again, plan.json listing every step once, and the
turn-on repeatability of its five power-cycled swings holds the emulated truth. Its swings last 40 s, not 120 s, and
its scale-factor test dwells 2 s, not 4 s: the same steps, in less time (a swing's bias is still known to a few ug,
against the 40 ug spread of the turn-on biases)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from hil.cli import main

ROOT = Path(__file__).resolve().parent.parent
PLAN = ROOT / "configs" / "plan_acceptance.yaml"


def started(out: Path, index: int) -> bool:
    """Whether plan.json says step ``index`` has started and not ended."""
    try:
        step = json.loads((out / "plan.json").read_text())["steps"][index - 1]
    except (OSError, ValueError):
        return False
    return step["started_utc"] is not None and step["ended"] is None


def shortened(tmp_path: Path) -> Path:
    """The shipped plan with its swings 40 s long and its scale-factor test's dwell 2 s, written to ``tmp_path``."""
    plan = yaml.safe_load(PLAN.read_text())
    plan["config"] = str(PLAN.parent / plan["config"])
    steps = plan["steps"]
    [swing] = [step["swing"] for step in steps[3]["repeat"]["steps"] if "swing" in step]
    swing["trial"]["duration_s"] = 40
    [scale_factor] = [step["scale_factor"] for step in steps if "scale_factor" in step]
    scale_factor["dwell_s"] = 2
    path = tmp_path / "plan_acceptance.yaml"
    path.write_text(yaml.safe_dump(plan))
    return path


@pytest.mark.slow
def test_the_acceptance_plan_killed_in_its_third_step_resumes_and_completes(tmp_path):
    out = tmp_path / "out"
    plan = shortened(tmp_path)
    argv = [sys.executable, "-m", "hil.cli", "plan", str(plan), "--out", str(out), "--speed", "max",
            "--no-history", "--no-figures"]
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not started(out, 3):
            time.sleep(0.05)
        assert started(out, 3), "the third step never started"
        time.sleep(2.0)  # into the calibration
        os.kill(process.pid, signal.SIGKILL)
        process.wait(30)
    finally:
        process.kill()
    before = json.loads((out / "plan.json").read_text())
    assert [s["ended"] for s in before["steps"][:3]] == ["completed", "completed", None]

    code = main(["plan", str(plan), "--out", str(out), "--resume", "--speed", "max", "--no-history",
                 "--no-figures"])
    after = json.loads((out / "plan.json").read_text())
    assert code in (0, 3) and after["ended"] == "completed" and after["run"] == before["run"]
    assert after["steps"][:2] == before["steps"][:2]  # not run again
    assert [s["index"] for s in after["steps"]] == list(range(1, 17))
    assert all(s["ended"] == "completed" for s in after["steps"])
    figures = after["units"]["imu"]
    assert figures["power_ons"] == 5
    for axis in range(3):
        low, high = figures["turn_on_repeatability_ci_ug"][axis]
        assert low < figures["truth_turn_on_bias_ug"][axis] < high
