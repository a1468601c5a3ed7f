"""A plan's soak step: the chamber sent to the temperature and watched through its controller until it holds it,
the trial steps after it at that set point, a chamber too slow for the timeout an early end."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from hil.cli import main

CONFIG = {"trial": {"name": "soak", "duration_s": 10, "rate_hz": 200, "seed": 7},
          "site": {"latitude_deg": 32.0, "longitude_deg": 118.0, "height_m": 10.0},
          "turntable": {"source": "emulator", "motion": {"kind": "static"}},
          "imu": {"source": "emulator", "protocol": "kvh1750"},
          "environment": {"chamber": {"source": "emulator", "set_point_c": 25, "tau_s": 120,
                                      "ramp_c_per_min_max": 5}}}


def run_plan(tmp_path: Path, soak: dict) -> tuple[int, dict]:
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(CONFIG))
    plan = tmp_path / "plan.yaml"
    plan.write_text(yaml.safe_dump({"name": "soak", "config": "config.yaml", "steps": [{"soak": soak},
                                                                                     {"swing": {}}]}))
    code = main(["plan", str(plan), "--out", str(tmp_path / "out"), "--speed", "max", "--no-history",
                 "--no-figures"])
    return code, json.loads((tmp_path / "out" / "plan.json").read_text())


def test_a_soak_waits_for_the_chamber_to_hold_the_temperature_and_the_trials_after_run_at_it(tmp_path):
    code, doc = run_plan(tmp_path, {"temperature_c": 40, "stable_within_c": 0.5, "for_s": 60, "timeout_s": 3600})
    assert code == 0 and doc["steps"][0]["ended"] == "completed"
    # 60 s ramp at 5 deg C/min to a 10 deg C gap, then tau 120 s to within 0.55 (the F4's 0.1 deg C reading of 39.5
    # is in): 408 s, in at the reading of 410 s, held for the readings up to 465 s
    assert doc["steps"][0]["soak"] == {"temperature_c": 39.7, "took_s": 465.0}
    step = yaml.safe_load((tmp_path / "out" / "configs" / "02-swing.yaml").read_text())
    assert step["environment"]["chamber"]["set_point_c"] == 40


def test_a_chamber_that_cannot_hold_the_temperature_in_time_ends_the_soak_early(tmp_path):
    code, doc = run_plan(tmp_path, {"temperature_c": 40, "stable_within_c": 0.5, "for_s": 60, "timeout_s": 300})
    assert code == 1 and doc["verdict"] == "ENDED EARLY"
    assert doc["steps"][0]["ended"].startswith("ended early: the chamber did not hold 40 deg C")
    assert doc["steps"][1]["ended"] is None
