"""The bias model in a trial's outputs: result.json keys, the drift check, series.csv columns, the summary."""

from __future__ import annotations

import csv
import json

import pytest
import yaml

from hil.cli import main

DRIFT_UG_PER_H = [600.0, -400.0, 500.0]


def _config(tmp_path, bias_model: str, drift=DRIFT_UG_PER_H):
    data = {
        "trial": {"name": f"drift-{bias_model}", "duration_s": 800.0, "rate_hz": 50.0, "seed": 5},
        "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
        "turntable": {"motion": {"kind": "swing", "axes": {
            "outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
            "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
            "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6}}}},
        "imu": {"source": "emulator", "errors": {"accel_bias_ug": [60, 150, 260], "accel_noise_ug": [50, 50, 50],
                                                 "accel_drift_ug_per_h": drift}},
        "estimator": {"bias_model": bias_model},
        "output": {"figures": False},
    }
    path = tmp_path / f"{bias_model}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _simulate(tmp_path, config, capsys):
    out = tmp_path / config.stem
    assert main(["simulate", str(config), "--out", str(out)]) == 0
    return json.loads((out / "result.json").read_text()), out, capsys.readouterr().out


def test_the_drift_model_reports_the_drift_rate_and_the_bias_at_both_ends(tmp_path, capsys):
    result, out, summary = _simulate(tmp_path, _config(tmp_path, "drift"), capsys)
    est = result["estimate"]
    assert est["bias_model"] == "drift" and result["truth"]["accel_drift_ug_per_h"] == DRIFT_UG_PER_H
    for k in range(3):
        error = est["accel_bias_drift_ug_per_h"][k] - DRIFT_UG_PER_H[k]
        assert abs(error) < 3 * est["accel_bias_drift_sigma_ug_per_h"][k]
        # the bias at the end is the bias at the start plus the drift over the trial
        expected_end = est["accel_bias_t0_ug"][k] + est["accel_bias_drift_ug_per_h"][k] * 800.0 / 3600.0
        assert est["accel_bias_ug"][k] == pytest.approx(expected_end, abs=1e-6)
    assert est["drift_check"]["drift_ug_per_h"] == pytest.approx(est["accel_bias_drift_ug_per_h"])
    assert "bias drift (ug/h)" in summary and "WARNING" not in summary
    with open(out / "series.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert float(rows[-1]["drift_x_ug_per_h"]) == pytest.approx(est["accel_bias_drift_ug_per_h"][0])
    assert float(rows[-1]["drift_sigma_z_ug_per_h"]) == pytest.approx(est["accel_bias_drift_sigma_ug_per_h"][2])


def test_the_constant_model_flags_an_unmodelled_drift(tmp_path, capsys):
    result, _, summary = _simulate(tmp_path, _config(tmp_path, "constant"), capsys)
    est = result["estimate"]
    assert est["bias_model"] == "constant" and "accel_bias_drift_ug_per_h" not in est
    assert est["drift_check"]["significant"] is True
    assert "WARNING: the bias drifts" in summary and "estimator.bias_model: drift" in summary
    table = result["table_reference"]  # the table-referenced fit sees the same drift, without the gyros
    drift, sigma = table["accel_bias_drift_ug_per_h"], table["accel_bias_drift_sigma_ug_per_h"]
    assert all(abs(k - truth) < 4 * s for k, s, truth in zip(drift, sigma, DRIFT_UG_PER_H))


def test_without_drift_the_check_stays_quiet(tmp_path, capsys):
    result, _, summary = _simulate(tmp_path, _config(tmp_path, "constant", drift=[0.0, 0.0, 0.0]), capsys)
    check = result["estimate"]["drift_check"]
    assert check["significant"] is False and "WARNING" not in summary
    assert all(abs(k) < 4 * s for k, s in zip(check["drift_ug_per_h"], check["sigma_ug_per_h"]))


def test_a_drift_the_table_reference_does_not_see_is_put_on_the_gyros(tmp_path, capsys):
    """A constant accelerometer bias under a 0.03 deg/h gyro bias for 4 h: the gyro turns i_b0, the 15-state drift
    check sees a drift of ~10 ug/h, the table-referenced fit (no gyro in it) none: the summary does not send the
    lab to the drift model."""
    config = _config(tmp_path, "constant", drift=[0.0, 0.0, 0.0])
    data = yaml.safe_load(config.read_text())
    data["trial"].update(duration_s=14400.0, rate_hz=20.0)
    data["imu"]["errors"]["gyro_bias_dph"] = [0.03, 0.03, 0.03]
    config.write_text(yaml.safe_dump(data))
    result, out, summary = _simulate(tmp_path, config, capsys)
    check, table = result["estimate"]["drift_check"], result["table_reference"]
    assert check["significant"] is True
    drift, sigma = table["accel_bias_drift_ug_per_h"], table["accel_bias_drift_sigma_ug_per_h"]
    assert all(abs(k) < 4 * s for k, s in zip(drift, sigma))
    assert "the table-referenced bias does not drift so" in summary and "estimator.bias_model: drift" not in summary
    assert "bias_drift_not_in_table_reference" in (out / "report.html").read_text()
