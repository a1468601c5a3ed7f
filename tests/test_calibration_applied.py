"""Which calibration a trial applied: result.json's ``calibration_applied``, the console summary, the report."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
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


def test_a_calibration_applied_to_a_swing_of_the_same_imu_and_table_leaves_no_bias_and_no_tilt(tmp_path):
    """``hil calibrate --simulate`` on configs/calibration_short.yaml, then a swing of the same emulated IMU and table
    (the same gimbal zero offsets) with ``imu.calibration``: the IMU's terms compensate its increments, the file's
    zero offsets correct the table's angles, so the table-referenced bias is the residual of the calibration (within
    a few micro-g) and the method-2 alignment error is the swing's noise level, not the zero offsets' 30 arcsec."""
    root = Path(__file__).resolve().parents[1]
    calibrated = tmp_path / "cal"
    assert main(["calibrate", str(root / "configs" / "calibration_short.yaml"), "--simulate", "--out", str(calibrated),
                 "--no-figures", "--viewer", "none"]) == 0
    source = yaml.safe_load((root / "configs" / "calibration_short.yaml").read_text())
    swing = yaml.safe_load((root / "configs" / "emulated_swing.yaml").read_text())
    swing["trial"]["duration_s"] = 300
    swing["turntable"]["zero_offset_arcsec"] = source["turntable"]["zero_offset_arcsec"]
    swing["imu"]["errors"] = source["imu"]["errors"]
    swing["imu"]["calibration"] = str(calibrated / "calibration.json")
    config = tmp_path / "swing.yaml"
    config.write_text(yaml.safe_dump(swing))
    out = tmp_path / "swing"
    main(["simulate", str(config), "--out", str(out), "--no-figures"])
    result = json.loads((out / "result.json").read_text())
    table = result["table_reference"]
    assert np.all(np.abs(table["accel_bias_ug"]) < 3 * np.array(table["accel_bias_sigma_ug"]) + 5.0), table
    assert abs(result["alignment_deg"]["method2"]["pitch"]) < 2e-3 and abs(result["alignment_deg"]["method2"]["roll"]) < 2e-3


def test_the_files_zero_offsets_are_added_to_the_table_angles_and_listed_as_applied(tmp_path):
    from hil.pipeline.compensation import CalibrationFileError, Compensation, applied_terms
    from hil.samples import TableSamples

    document = {**DOCUMENT, "turntable": {"zero_offset_arcsec": [36.0, -18.0, None]}}
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(document))
    angles = np.array([[0.1, -0.2, 0.3], [0.4, 0.5, -0.6]])
    table = TableSamples(np.arange(2), angles, np.zeros(2), np.zeros(2), np.zeros(2, int))
    corrected = Compensation(path, 0.005).table(table).angles
    arcsec = np.pi / (180 * 3600)
    np.testing.assert_allclose(corrected - angles, [[36 * arcsec, -18 * arcsec, 0.0]] * 2, rtol=1e-12, atol=1e-18)
    applied = applied_terms(document)
    assert applied["terms"]["turntable"] == ["zero_offset_arcsec"] and "turntable.zero_offset_arcsec.2" in applied["null_terms"]
    path.write_text(json.dumps({**DOCUMENT, "turntable": {"zero_offset_arcsec": [1.0, "x", 0.0]}}))
    with pytest.raises(CalibrationFileError, match=r"turntable.zero_offset_arcsec\[1\]: expected a finite number"):
        Compensation(path, 0.005)
