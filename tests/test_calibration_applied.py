"""Which calibration a trial applied: result.json's ``calibration_applied``, the console summary, the report."""

from __future__ import annotations

import hashlib
import json

import yaml

from hil.cli import main

DOCUMENT = {"accel": {"bias_ug": [10.0, None, -5.0], "scale_ppm": [100, -50, 30], "misalignment_arcsec": [0] * 6,
                      "nonlinearity_ug_per_g2": [None] * 3},
            "gyro": {"bias_dph": [0.01, 0.01, 0.01], "scale_ppm": [0, 0, 0], "misalignment_arcsec": [1] * 6}}


def _config(tmp_path, calibration=None):
    imu = {"source": "emulator", "errors": {"accel_bias_ug": [60, 150, 260], "accel_noise_ug": [50, 50, 50]}}
    if calibration is not None:
        imu["calibration"] = str(calibration)
    data = {"trial": {"name": "applied", "duration_s": 30.0, "rate_hz": 50.0, "seed": 3},
            "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
            "turntable": {"motion": {"kind": "swing", "axes": {
                "outer": {"amplitude_deg": 8, "period_s": 8}, "middle": {"amplitude_deg": 6, "period_s": 10},
                "inner": {"amplitude_deg": 13, "period_s": 8}}}},
            "imu": imu, "output": {"figures": False}}
    path = tmp_path / f"trial-{calibration is not None}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _simulate(tmp_path, config, capsys):
    out = tmp_path / config.stem
    assert main(["simulate", str(config), "--out", str(out), "--no-figures"]) == 0
    return json.loads((out / "result.json").read_text()), (out / "report.html").read_text(), capsys.readouterr().out


def test_a_trial_with_imu_calibration_names_the_file_its_digest_and_the_terms_applied(tmp_path, capsys):
    calibration = tmp_path / "calibration.json"
    calibration.write_text(json.dumps(DOCUMENT))
    result, report, summary = _simulate(tmp_path, _config(tmp_path, calibration), capsys)
    applied = result["calibration_applied"]
    assert applied["path"] == str(calibration)
    assert applied["sha256"] == hashlib.sha256(calibration.read_bytes()).hexdigest()
    # a key is applied when any of its terms is a number; a null term is left uncompensated and listed
    assert applied["terms"] == {"accel": ["bias_ug", "scale_ppm", "misalignment_arcsec"],
                                "gyro": ["bias_dph", "scale_ppm", "misalignment_arcsec"]}
    assert applied["null_terms"] == ["accel.bias_ug.1"] + [f"accel.nonlinearity_ug_per_g2.{i}" for i in range(3)]
    line = (f"calibration applied: {calibration} (sha256 {applied['sha256'][:12]}): accel bias, scale, "
            "misalignment; gyro bias, scale, misalignment, 4 null terms not applied")
    assert [s.strip() for s in summary.splitlines()].count(line) == 1
    assert line in report


def test_a_trial_without_imu_calibration_says_none_was_applied(tmp_path, capsys):
    result, report, summary = _simulate(tmp_path, _config(tmp_path), capsys)
    assert "calibration_applied" in result and result["calibration_applied"] is None
    assert "no calibration applied (imu.calibration not set)" in report and "calibration" not in summary
