"""``hil calibrate`` end to end on the emulated table, its refusals, and ``imu.calibration`` applied to a trial."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil.cli import main
from hil.outputs.calibration_report import comparison
from hil.pytest_plugin import read_cases

IMU_ERRORS = {
    "accel_bias_ug": [60, 150, 260], "accel_noise_ug": [50, 50, 50], "accel_scale_ppm": [120, -250, 300],
    "accel_misalignment_arcsec": [12, -20, 30, 15, -25, 8], "accel_nonlinearity_ug_per_g2": [20, -30, 40],
    "gyro_bias_dph": [0.02, -0.03, 0.05], "gyro_noise_dph": [0.01, 0.01, 0.01], "gyro_scale_ppm": [50, -80, 150],
    "gyro_misalignment_arcsec": [-10, 6, 14, -9, 22, -5]}


def calibration_config(tmp_path, **calibration):
    cfg = {
        "trial": {"name": "calibration-test", "rate_hz": 200, "seed": 11},
        "site": {"latitude_deg": 32.0, "longitude_deg": 118.0, "height_m": 10.0},
        "turntable": {"source": "emulator", "command_port": "emulator", "latch_delay_us": 50,
                      "motion": {"kind": "static"},
                      "limits": {"rate_dps": [60, 60, 60], "accel_dps2": [120, 120, 120]},
                      "zero_offset_arcsec": [35, 30, -20]},
        "imu": {"source": "emulator", "protocol": "kvh1750", "errors": IMU_ERRORS},
        "calibration": {"positions": 18, "dwell_s": 4, "settle_s": 0.5, "plateau_rate_dps": 30, "plateau_s": 10,
                        **calibration},
        "output": {"limits": {"calibration_residual_ug_max": 30, "calibration_error_sigma_max": 4}},
    }
    path = tmp_path / "calibration.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.mark.slow
def test_an_emulated_calibration_recovers_every_term_and_removes_the_bias_of_a_later_swing(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["calibrate", str(calibration_config(tmp_path)), "--speed", "max", "--viewer", "none",
                 "--out", str(out), "--quiet", "--no-figures"])
    failed = [case for case in read_cases(out / "junit.xml") if case.outcome != "passed"] if code == 3 else []
    assert code == 0, (capsys.readouterr().err, failed)  # which limit a FAIL missed, and by how much
    doc = json.loads((out / "calibration.json").read_text())
    rows = comparison(doc)
    judged = [r for r in rows if r["error_sigma"] is not None]
    assert len(judged) == len(rows) - 1  # all but the inner zero offset, reported unobservable
    assert "turntable.zero_offset_arcsec.2" in doc["unobservable"]
    # ~30 terms at once: 4 sigma bounds the family at about 0.2 % (3 sigma would fail one run in ten)
    errors = np.array([r["error_sigma"] for r in judged])
    assert np.all(np.abs(errors) < 4.0), [(r["term"], r["error_sigma"]) for r in judged]
    assert np.sqrt(np.mean(errors**2)) < 1.5  # and as a whole they are errors of the size their sigmas say
    # each window holds its dwell's 800 samples, less any the gates took out on a loaded machine
    samples = [p["samples"] for p in doc["positions"]]
    assert len(samples) == 18 and all(720 <= n <= 800 for n in samples), f"{samples}"
    result = json.loads((out / "result.json").read_text())
    assert result["ended"] == "completed" and result["calibration"]["residual_max_ug"] < 30
    assert (out / "calibration.html").exists() and (out / "junit.xml").exists()
    stats = json.loads((out / "emulator.json").read_text())
    assert stats["table_modes"] == "Off,Off,Off"  # sent Off at the end
    # the positions' specific force after the calibration matches gravity to the noise: 50 ug over each
    # window's samples (and the accelerometers' share of the fit's own uncertainty)
    residuals = np.array([p["residual_ug"] for p in doc["positions"]])
    assert np.sqrt(np.mean(residuals**2)) < 3 * 50.0 / np.sqrt(720)
    # round trip: the same IMU swung with its calibration applied has no bias left, within 4 sigma
    swing = yaml.safe_load(Path("configs/emulated_swing.yaml").read_text())
    swing["trial"]["duration_s"] = 300
    swing["imu"]["errors"] = IMU_ERRORS
    swing["imu"]["calibration"] = str(out / "calibration.json")
    swing.pop("output", None)
    (tmp_path / "swing.yaml").write_text(yaml.safe_dump(swing))
    assert main(["simulate", str(tmp_path / "swing.yaml"), "--out", str(tmp_path / "swing"), "--no-figures"]) == 0
    estimate = json.loads((tmp_path / "swing" / "result.json").read_text())["estimate"]
    calibration_sigma = doc["sigma"]["accel"]["bias_ug"]  # the bias the calibration took out is uncertain too
    for bias, sigma, cal in zip(estimate["accel_bias_ug"], estimate["accel_bias_sigma_ug"], calibration_sigma,
                                strict=True):
        assert abs(bias) < 4 * np.hypot(sigma, cal), (estimate["accel_bias_ug"], estimate["accel_bias_sigma_ug"])


def test_a_schedule_outside_the_table_limits_is_refused_naming_the_position(tmp_path, capsys):
    path = calibration_config(tmp_path, positions=[[0, 0, 0], [0, 95, 0]])
    assert main(["calibrate", str(path), "--viewer", "none", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "position 2: middle angle 95 deg is outside the table limits" in err and err.count("\n") == 1
    assert not (tmp_path / "out" / "ports.json").exists()  # nothing was started


def swing_config(tmp_path, calibration=None):
    cfg = yaml.safe_load(Path("configs/emulated_swing.yaml").read_text())
    cfg["trial"]["duration_s"] = 300
    cfg["imu"]["errors"] = {"accel_bias_ug": [60, 150, 260], "accel_noise_ug": [50, 50, 50],
                            "accel_scale_ppm": [800, -600, 900],
                            "accel_misalignment_arcsec": [60, -40, 50, 30, -70, 40],
                            "gyro_bias_dph": [0.01, 0.01, 0.01], "gyro_noise_dph": [0.01, 0.01, 0.01],
                            "gyro_scale_ppm": [300, -200, 400], "gyro_misalignment_arcsec": [20, -30, 10, 40, -20, 30]}
    cfg.pop("output", None)
    if calibration is not None:
        cfg["imu"]["calibration"] = str(calibration)
    path = tmp_path / f"swing-{calibration is not None}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path, cfg["imu"]["errors"]


def test_a_swing_trial_with_the_calibration_applied_estimates_the_bias_better(tmp_path):
    plain, errors = swing_config(tmp_path)
    document = {"accel": {"bias_ug": [None] * 3, "scale_ppm": errors["accel_scale_ppm"],
                          "misalignment_arcsec": errors["accel_misalignment_arcsec"],
                          "nonlinearity_ug_per_g2": [0, 0, 0]},
                "gyro": {"bias_dph": errors["gyro_bias_dph"], "scale_ppm": errors["gyro_scale_ppm"],
                         "misalignment_arcsec": errors["gyro_misalignment_arcsec"]}}
    calibration = tmp_path / "calibration.json"
    calibration.write_text(json.dumps(document))
    applied, _ = swing_config(tmp_path, calibration)
    bias_errors = []
    for path in (plain, applied):
        out = tmp_path / path.stem
        assert main(["simulate", str(path), "--out", str(out), "--no-figures"]) == 0
        result = json.loads((out / "result.json").read_text())
        bias_errors.append(max(abs(e - t) for e, t in zip(result["estimate"]["accel_bias_ug"],
                                                           result["truth"]["accel_bias_ug"], strict=True)))
    # the scale and misalignment errors leak into the swing's bias estimate; compensated, only the noise is left
    assert bias_errors[1] < bias_errors[0] / 3 and bias_errors[1] < 5.0, bias_errors


def test_a_bad_calibration_file_is_one_line_naming_the_key(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"accel": {"bias_ug": [1, 2]}}))
    path, _ = swing_config(tmp_path, bad)
    assert main(["simulate", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hil: error: imu.calibration: ") and str(bad) in err and err.count("\n") == 1
