"""Terms a schedule cannot observe, by the fit's own rank and sigma: written null with the reason, never applied."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from test_calibration import EARTH, GEOMETRY, GYRO, ZERO, synthetic_windows

from hil.cli import main
from hil.estimation.calibration_model import INDEX
from hil.estimation.calibration_schedule import Dwell, Plateau, Schedule
from hil.estimation.gyro_calibration import calibrate_gyros
from hil.pipeline.compensation import Compensation, applied_terms
from hil.units import DEG, DEG_PER_H, PPM, UG

ROOT = Path(__file__).resolve().parents[1]
RATE_TABLE = Schedule((Dwell((0.0, 0.0, 0.0), 10.0, 0.5),),
                      tuple(Plateau((0.0, 0.0, 0.0), 0, sign * 30 * DEG, 10.0, 0.5) for sign in (1, -1)))


def test_a_scale_factor_seen_only_through_the_earth_rate_is_unobservable_and_held_at_zero():
    """z up, turning about the vertical: the x and y gyros see only the earth's 12.7 deg/h horizontal rate. Their
    scale columns are independent of the bias's (the rank test keeps them), but their sigmas, as the effect at the
    schedule's 30 deg/s, are thousands of times the bias's: left out, held at zero, the bias refitted without them."""
    windows = synthetic_windows(RATE_TABLE, {"bias": np.zeros(3), "scale": np.zeros(3), "mis": np.zeros(6),
                                             "knl": np.zeros(3)}, GYRO, ZERO * 0, 50 * UG, 0.01 * DEG_PER_H,
                                np.random.default_rng(4))
    fit = calibrate_gyros(windows, EARTH, GEOMETRY, fit=("bias", "scale"))
    assert set(fit.unobservable) == {"scale_x", "scale_y"}
    assert all("too weakly excited" in fit.unobservable[t] for t in ("scale_x", "scale_y"))
    assert fit.theta[INDEX["scale_x"]] == 0.0 and fit.theta[INDEX["scale_y"]] == 0.0
    assert np.isnan(fit.sigma[INDEX["scale_x"]]) and np.isnan(fit.sigma[INDEX["scale_y"]])
    z = INDEX["scale_z"]
    assert abs(fit.theta[z] - GYRO["scale"][2]) < 0.01 * PPM and fit.sigma[z] < 0.01 * PPM


def test_the_rate_table_calibration_writes_the_x_and_y_gyro_scales_null_and_a_trial_applies_neither(tmp_path):
    """``hil calibrate configs/calibration_rate_table.yaml --simulate``: the x / y gyro scales (955 +- 1827 and
    -83 +- 26 ppm before) are null with the reason; the z scale is the fit's (150 ppm); the file applies no x / y
    scale."""
    out = tmp_path / "out"
    assert main(["calibrate", str(ROOT / "configs" / "calibration_rate_table.yaml"), "--simulate", "--viewer", "none",
                 "--no-figures", "--quiet", "--no-history", "--out", str(out)]) == 0
    path = out / "calibration.json"
    doc = json.loads(path.read_text())
    assert doc["gyro"]["scale_ppm"][:2] == [None, None] and doc["sigma"]["gyro"]["scale_ppm"][:2] == [None, None]
    assert abs(doc["gyro"]["scale_ppm"][2] - 150.0) < 3 * doc["sigma"]["gyro"]["scale_ppm"][2] + 0.01
    for i in (0, 1):
        assert "too weakly excited by this schedule" in doc["unobservable"][f"gyro.scale_ppm.{i}"]
    assert {"gyro.scale_ppm.0", "gyro.scale_ppm.1"} <= set(applied_terms(doc)["null_terms"])
    gyro = Compensation(path, 0.005).gyro
    assert gyro[INDEX["scale_x"]] == 0.0 and gyro[INDEX["scale_y"]] == 0.0
    assert abs(gyro[INDEX["scale_z"]] / PPM - 150.0) < 0.01
