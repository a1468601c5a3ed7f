"""Per-window residuals before and after calibration (calibration.html's figure) against the model written out
independently in tests/test_calibration.py."""

from __future__ import annotations

import io

import numpy as np
from test_calibration import (
    ACCEL,
    EARTH,
    GEOMETRY,
    GYRO,
    ZERO,
    body_from_n,
    earth_rate_n,
    gimbal_rate_body,
    paper_c_pa,
    run,
)

from hil.estimation.calibration_schedule import default_schedule
from hil.outputs.calibration import calibration_document
from hil.outputs.calibration_report import window_residuals, write_calibration_report, write_residual_figure
from hil.units import DEG_PER_H, UG


def _errors(errors, reference):
    """What an error-free model leaves of the sensor of Eq. (6) at the true angles: y - r."""
    v = np.diag(1.0 + errors["scale"]) @ paper_c_pa(*errors["mis"]) @ reference
    return v + errors["knl"] * v**2 + errors["bias"] - reference


def test_before_is_the_sensor_error_plus_the_zero_offsets_and_after_is_zero_without_noise():
    schedule = default_schedule(plateau_s=20.0)
    windows, acc, gyr = run(schedule, accel_noise=0.0, gyro_noise=0.0)
    residuals = window_residuals(windows, acc, gyr, EARTH, GEOMETRY)
    assert residuals.accel_before.shape == (18, 3) and residuals.gyro_before.shape == (24, 3)
    for k, dwell in enumerate(schedule.dwells):
        true = body_from_n(np.array(dwell.angles) + ZERO) @ [0.0, 0.0, EARTH.g]
        nominal = body_from_n(np.array(dwell.angles)) @ [0.0, 0.0, EARTH.g]
        expected = _errors(ACCEL, true) + true - nominal
        assert np.allclose(residuals.accel_before[k], expected, rtol=0, atol=1e-3 * UG)
        expected = _errors(GYRO, body_from_n(np.array(dwell.angles) + ZERO) @ earth_rate_n())
        expected += (body_from_n(np.array(dwell.angles) + ZERO) - body_from_n(np.array(dwell.angles))) @ earth_rate_n()
        assert np.allclose(residuals.gyro_before[k], expected, rtol=0, atol=1e-6 * DEG_PER_H)
    for k, plateau in enumerate(schedule.plateaus):  # the encoder rows of synthetic_windows
        rates = np.zeros(3)
        rates[plateau.axis] = plateau.rate
        t = (np.arange(24) + 0.5) / 24 * plateau.duration_s
        encoder = np.array(plateau.angles) + np.outer(t, rates)
        true, nominal = (np.mean([body_from_n(a + zero) @ earth_rate_n() + gimbal_rate_body(a + zero, rates)
                                  for a in encoder], axis=0) for zero in (ZERO, np.zeros(3)))
        expected = _errors(GYRO, true) + true - nominal
        assert np.allclose(residuals.gyro_before[18 + k], expected, rtol=0, atol=1e-6 * DEG_PER_H)
        # along the turning axis the scale error times the rate dominates (150 ppm of 10 deg/s is 5.4 deg/h)
        j = int(np.argmax(np.abs(nominal)))
        assert abs(residuals.gyro_before[18 + k][j]) > 0.5 * abs(GYRO["scale"][j] * nominal[j])
    # after: the fitted model leaves nothing
    assert np.max(np.abs(residuals.accel_after)) < 1e-6 * UG
    assert np.max(np.abs(residuals.gyro_after)) < 1e-6 * DEG_PER_H


def test_the_report_embeds_the_accelerometer_and_gyro_figure(tmp_path):
    import matplotlib.image

    windows, acc, gyr = run(default_schedule(plateau_s=20.0), seed=3)
    doc = calibration_document(acc, gyr, windows)
    result = {"trial": {"name": "six-position"}, "ended": "completed", "record": {"dut_serial": "SN 9"}}
    image = write_residual_figure(tmp_path, window_residuals(windows, acc, gyr, EARTH, GEOMETRY))
    write_calibration_report(tmp_path, doc, result, "PASS", image)
    page = (tmp_path / "calibration.html").read_text()
    assert page.count("<img") == 1 and "data:image/png;base64," in page
    assert "<h1>six-position</h1>" in page and "SN 9" in page and 'class="verdict PASS"' in page
    image = matplotlib.image.imread(io.BytesIO((tmp_path / "calibration_residuals.png").read_bytes()))
    assert image.shape[1] == 2 * 9 * 90  # two columns of panels: specific force and angular rate
    without = tmp_path / "accel-only"
    without.mkdir()
    write_residual_figure(without, window_residuals(windows, acc, None, EARTH, GEOMETRY))
    image = matplotlib.image.imread(io.BytesIO((without / "calibration_residuals.png").read_bytes()))
    assert image.shape[1] == 9 * 90
