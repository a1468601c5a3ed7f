"""Campaigns without a cluster: the SPEC, the seeds, one run and its row, runs.parquet, and the statistics
of summary.json against an independent derivation (the coverage of their bands on synthetic errors)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil.campaign.runner import resumed_rows
from hil.campaign.runs import failed_row, flatten, run_swing
from hil.campaign.spec import RunTask, SpecError, check_key, load_campaign, run_seeds
from hil.campaign.swing_summary import bias_error, consistency, nees_band, ratio_band, summarise
from hil.campaign.table import read_runs, to_table, write_runs

ROOT = Path(__file__).resolve().parent.parent
LIU = ROOT / "configs" / "liu2019_sim.yaml"


def _spec(tmp_path: Path, sweep: dict, runs: int = 3) -> Path:
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"base": str(LIU), "runs": runs, "seed": 5, "sweep": sweep}))
    return path


def _campaign_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil.cli", "campaign", *args], check=False, cwd=cwd,
                          capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})


def test_sweep_expands_to_every_combination_with_the_same_seeds_at_each_point(tmp_path):
    campaign = load_campaign(_spec(tmp_path, {"trial.duration_s": [20, 40], "turntable.motion.axes.inner.amplitude_deg":
                                              [5, 10, 13]}))
    assert len(campaign.points) == 6 and len(campaign.tasks) == 18
    assert campaign.points[1] == {"trial.duration_s": 20, "turntable.motion.axes.inner.amplitude_deg": 10}
    seeds = run_seeds(5, 3)
    for task in campaign.tasks:
        assert task.seed == seeds[task.run] == task.config["trial"]["seed"]
        assert task.config["trial"]["duration_s"] == campaign.points[task.point]["trial.duration_s"]
        assert task.config["turntable"]["motion"]["axes"]["inner"]["amplitude_deg"] == task.values[
            "turntable.motion.axes.inner.amplitude_deg"]
        assert task.config["turntable"]["motion"]["axes"]["outer"]["amplitude_deg"] == 8  # the base's
    assert len(set(seeds)) == 3 and all(0 <= s < 2**63 for s in seeds)


def test_seeds_are_the_spawned_children_and_more_runs_keep_the_first_ones():
    children = np.random.SeedSequence(11).spawn(4)
    assert run_seeds(11, 4) == [int(c.generate_state(1, np.uint64)[0]) >> 1 for c in children]
    assert run_seeds(11, 10)[:4] == run_seeds(11, 4)


AXES = {"outer": {"amplitude_deg": 4, "period_s": 6}, "middle": {"amplitude_deg": 3, "period_s": 9}}


@pytest.mark.parametrize(("key", "values"), [("imu.errors.accel_noise_ug", [[10, 10, 10], [20, 30, 40]]),
                                             ("trial.duration_s", [30.0, 90.0]),
                                             ("imu.can.bitrate", [250000, 1000000]),
                                             ("turntable.motion.axes", [AXES, {"inner": {"amplitude_deg": 2, "period_s": 5}}])])
def test_a_swept_config_key_reaches_each_points_config(tmp_path, key, values):
    check_key(key)
    tasks = load_campaign(_spec(tmp_path, {key: values}, runs=1)).tasks
    found = []
    for task in tasks:
        block = task.config
        for part in key.split("."):
            block = block[part]
        found.append(block)
    assert found == values and [t.values for t in tasks] == [{key: v} for v in values]


@pytest.mark.parametrize(("key", "named"), [("imu.errors.accel_noise", "'imu.errors.accel_noise'"),
                                            ("trial.duration_s.x", "trial.duration_s is a value"),
                                            ("imux.errors", "'imux'")])
def test_unknown_keys_are_named(key, named):
    with pytest.raises(SpecError, match=f"sweep.{key}: .*{named}"):
        check_key(key)


def test_unknown_sweep_key_exits_2_with_one_line_naming_it(tmp_path):
    proc = _campaign_cli(str(_spec(tmp_path, {"imu.errors.accel_nois_ug": [[1, 1, 1]]})), "--out", "o", cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "sweep.imu.errors.accel_nois_ug: unknown key" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_a_value_the_config_rejects_exits_2_with_its_message_before_any_run(tmp_path):
    proc = _campaign_cli(str(_spec(tmp_path, {"trial.duration_s": [30, -5]})), "--out", "o", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "sweep point trial.duration_s=-5: trial.duration_s: Input should be greater than 0" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_spec_errors_name_the_key(tmp_path):
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump({"base": str(LIU), "runs": 0, "sweeps": {}}))
    with pytest.raises(SpecError, match="runs: Input should be greater than 0; sweeps: unknown key"):
        load_campaign(tmp_path / "bad.yaml")
    with pytest.raises(SpecError, match="sweep point imu.calibration=missing.json: imu.calibration: missing.json"):
        load_campaign(_spec(tmp_path, {"imu.calibration": ["missing.json"]}))


def test_flatten_gives_dotted_scalars_lists_by_index_and_null_for_non_finite():
    doc = {"a": {"b": [1.5, np.float64(2.0), float("nan")], "c": None, "d": {"e": True}}, "n": np.int64(3)}
    assert flatten(doc) == {"a.b.0": 1.5, "a.b.1": 2.0, "a.b.2": None, "a.c": None, "a.d.e": True, "n": 3}
    assert type(flatten(doc)["n"]) is int


def _task(config: dict, values: dict | None = None) -> RunTask:
    return RunTask("p000-r0000", 0, 0, config["trial"]["seed"], values or {}, config)


def test_one_run_is_the_simulated_trial_flattened(tmp_path):
    from hil.config import parse_config
    from hil.trial.offline import run_simulation
    from hil.trial.viewer_feed import ViewerOptions

    config = yaml.safe_load(LIU.read_text())
    config["trial"].update(duration_s=40.0, rate_hz=20.0, seed=123)
    row = run_swing(_task(config, {"trial.duration_s": 40.0}))
    outcome, _ = run_simulation(parse_config(config), "", tmp_path, ViewerOptions())
    assert row["error"] is None and row["sweep.trial.duration_s"] == 40.0 and row["seed"] == 123
    assert [row[f"estimate.accel_bias_ug.{i}"] for i in range(3)] == outcome.result["estimate"]["accel_bias_ug"]
    assert row["trial.samples"] == 800 and row["truth.accel_bias_ug.2"] == 260.0
    assert not list(tmp_path.iterdir())  # a run writes nothing


def test_a_run_that_raises_is_a_row_with_its_error():
    config = yaml.safe_load(LIU.read_text())
    del config["trial"]["duration_s"]
    row = run_swing(_task(config))
    assert row["id"] == "p000-r0000" and "trial.duration_s: required key is missing" in row["error"]
    assert "estimate.accel_bias_ug.0" not in row


def _rows(errors: np.ndarray, sigma: float, point: int = 0) -> list[dict]:
    return [{"id": f"p{point:03d}-r{k:04d}", "point": point, "run": k, "seed": k, "error": None,
             **flatten({"estimate": {"accel_bias_ug": list(60.0 + e), "accel_bias_sigma_ug": [sigma] * 3,
                                     "bias_model": "constant", "converged_at_s": 10.0 * k},
                        "truth": {"accel_bias_ug": [60.0] * 3}})} for k, e in enumerate(errors)]


def test_parquet_rows_are_ordered_by_point_and_run_and_read_back(tmp_path):
    rows = _rows(np.zeros((3, 3)), 1.0) + _rows(np.ones((2, 3)), 1.0, point=1)
    rows.insert(1, failed_row(_task({"trial": {"seed": 9}}), RuntimeError("worker lost")) | {"point": 1, "run": 5})
    write_runs(tmp_path, rows[::-1])
    back = read_runs(tmp_path)
    assert [(r["point"], r["run"]) for r in back] == [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 5)]
    assert back[-1]["error"] == "RuntimeError: worker lost" and back[-1]["estimate.accel_bias_ug.0"] is None
    assert to_table(back).equals(to_table(rows))


def test_resume_keeps_done_runs_reruns_failed_ones_and_refuses_another_specs_table(tmp_path):
    campaign = load_campaign(_spec(tmp_path, {"trial.duration_s": [30]}, runs=3))
    tasks = campaign.tasks
    done = {**failed_row(tasks[0], "x"), "error": None, "estimate.accel_bias_ug.0": 1.0}
    write_runs(tmp_path, [done, failed_row(tasks[1], "worker lost")])
    assert [r["id"] for r in resumed_rows(campaign, tmp_path)] == [tasks[0].id]
    write_runs(tmp_path, [{**done, "seed": tasks[0].seed + 1}])
    with pytest.raises(SpecError, match="run p000-r0000 is not one of"):
        resumed_rows(campaign, tmp_path)


def test_drift_model_errors_are_against_the_truth_at_the_trial_end():
    row = flatten({"estimate": {"accel_bias_ug": [70.0, 0.0, 0.0], "accel_bias_sigma_ug": [1.0] * 3,
                                "bias_model": "drift"}, "trial": {"duration_s": 1800.0},
                   "truth": {"accel_bias_ug": [60.0, 0.0, 0.0], "accel_drift_ug_per_h": [20.0, 0.0, 0.0]}})
    assert bias_error(row).tolist() == [0.0, 0.0, 0.0]


def test_bands_match_their_large_sample_normal_approximations():
    m = 20001
    low, high = ratio_band(m)  # std of a sample std: sigma / sqrt(2 (M - 1))
    assert low == pytest.approx(1 - 1.959964 / math.sqrt(2 * (m - 1)), abs=2e-5)
    assert high == pytest.approx(1 + 1.959964 / math.sqrt(2 * (m - 1)), abs=2e-5)
    low, high = nees_band(m)  # var of a chi2(3) is 6
    assert (low, high) == pytest.approx((3 - 1.959964 * math.sqrt(6 / m), 3 + 1.959964 * math.sqrt(6 / m)), abs=1e-4)


def test_bands_hold_95_percent_of_consistent_campaigns_and_flag_an_optimistic_sigma():
    rng = np.random.default_rng(42)
    sigma, m, campaigns = np.array([2.0, 5.0, 0.5]), 30, 4000
    inside_ratio, inside_nees = np.zeros(3), 0
    for _ in range(campaigns):
        errors = rng.normal(0.0, sigma, (m, 3))
        s = consistency(errors, np.tile(sigma, (m, 1)))
        inside_ratio += s["ratio_inside"]
        inside_nees += s["nees_inside"]
    binomial = 4 * math.sqrt(0.95 * 0.05 / campaigns)
    assert np.all(np.abs(inside_ratio / campaigns - 0.95) < binomial)
    assert abs(inside_nees / campaigns - 0.95) < binomial
    errors = rng.normal(0.0, sigma, (200, 3))
    s = consistency(errors, np.tile(0.75 * sigma, (200, 1)))  # a sigma reported 25 % too small
    assert not any(s["ratio_inside"]) and not s["nees_inside"]


def test_summary_per_point_counts_failures_and_gives_convergence_quantiles(tmp_path):
    rng = np.random.default_rng(1)
    rows = _rows(rng.normal(0, 1, (11, 3)), 1.0) + [failed_row(_task({"trial": {"seed": 1}}), "boom")]
    summary = summarise([{"trial.duration_s": 30}], rows, {"scheduler": "tcp://127.0.0.1:1", "workers": 2})
    point = summary["points"][0]
    assert summary["failed"] == point["failed"] == 1 and point["runs"] == 12 and summary["cluster"]["workers"] == 2
    assert point["converged_at_s"] == {"q05": 5.0, "q50": 50.0, "q95": 95.0}
    errors = np.array([bias_error(r) for r in rows[:11]])
    assert point["error_std_ug"] == pytest.approx(np.std(errors, axis=0, ddof=1))
    json.dumps(summary, allow_nan=False)


def test_the_summary_is_the_same_bit_for_bit_whatever_order_the_runs_completed_in():
    rows = _rows(np.random.default_rng(3).normal(0, 1e-3, (40, 3)) * np.pi, 0.7)  # sums whose last bits move
    cluster = {"scheduler": "tcp://127.0.0.1:1", "workers": 2}
    first = json.dumps(summarise([{}], rows, cluster))
    shuffled = [rows[k] for k in np.random.default_rng(4).permutation(len(rows))]
    assert json.dumps(summarise([{}], shuffled, cluster)) == first


def test_the_shipped_example_sweeps_amplitude_and_duration_of_the_papers_swing():
    campaign = load_campaign(ROOT / "configs" / "campaign_swing.yaml")
    assert len(campaign.points) == 4 and len(campaign.tasks) == 4 * campaign.spec.runs
    assert {tuple(p) for p in campaign.points} == {("turntable.motion.axes.inner.amplitude_deg", "trial.duration_s")}
    assert campaign.tasks[0].config["imu"]["errors"]["accel_noise_ug"] == [50, 50, 50]


def test_a_base_that_reads_devices_is_refused_in_one_line_before_any_run(tmp_path):
    proc = _campaign_cli(str(_spec(tmp_path, {"imu.source": ["serial"], "imu.port": ["/dev/ttyUSB0"]})), "--out", "o",
                         cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "imu.source: serial: hil campaign emulates the devices" in proc.stderr
    assert not (tmp_path / "o").exists()
