"""The emulated IMU's thermal model (imu.errors.thermal): its temperature against the first-order step response
and the warm-up, its biases and scale factors against their polynomials at a temperature, and the emulated
world's chamber at environment.chamber.set_point_c."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from emulators.sensor_errors import SensorErrorModel
from emulators.simulation import emulated_world
from hil.config import load_config
from hil.config_emulated import ImuErrors
from hil.units import DEG_PER_H, UG

RATE = 100.0
THERMAL = {"reference_c": 25.0, "accel_bias_ug_per_c": [10.0, -20.0, 5.0], "accel_bias_ug_per_c2": [0.5, 0.1, -0.2],
           "gyro_bias_dph_per_c": [0.02, -0.01, 0.03], "accel_scale_ppm_per_c": [2.0, 0.0, -1.0],
           "gyro_scale_ppm_per_c": [-3.0, 1.0, 4.0], "case_tau_s": 600.0, "self_heating_c": 0.0,
           "warmup_tau_s": 300.0}


def _model(start_c: float, chamber_c: float, **thermal) -> SensorErrorModel:
    return SensorErrorModel(ImuErrors(temperature_c=start_c, thermal={**THERMAL, **thermal}), RATE, 1, chamber_c)


def test_the_sensor_follows_a_chamber_step_through_the_case_time_constant():
    model = _model(start_c=25.0, chamber_c=-40.0)
    t = np.array([0.0, 600.0, 1800.0])
    assert model.temperature_c(t) == pytest.approx([25.0, -40.0 + 65.0 / math.e, -40.0 + 65.0 * math.exp(-3.0)])


def test_self_heating_after_power_on_rises_with_the_warm_up_time_constant():
    model = _model(start_c=25.0, chamber_c=25.0, self_heating_c=4.0, warmup_tau_s=300.0)
    assert model.temperature_c(np.array([0.0, 300.0, 1e6])) == pytest.approx([25.0, 25.0 + 4.0 * (1 - 1 / math.e),
                                                                               29.0])


def test_biases_and_scale_factors_are_the_polynomials_at_the_sensor_temperature():
    model = _model(start_c=70.0, chamber_c=70.0)  # soaked: dT = 45 deg C throughout
    n, d = 200, 45.0
    t = np.arange(1, n + 1) / RATE
    rate = np.array([0.5, -1.0, 2.0])  # rad/s
    specific_force = np.array([0.0, 0.0, 9.8])  # m/s^2
    dtheta, dv = model.apply(t, np.tile(rate / RATE, (n, 1)), np.tile(specific_force / RATE, (n, 1)))
    c = THERMAL
    gyro = rate * (1 + np.array(c["gyro_scale_ppm_per_c"]) * 1e-6 * d) + np.array(c["gyro_bias_dph_per_c"]) * d * DEG_PER_H
    accel = (specific_force * (1 + np.array(c["accel_scale_ppm_per_c"]) * 1e-6 * d)
             + (np.array(c["accel_bias_ug_per_c"]) * d + np.array(c["accel_bias_ug_per_c2"]) * d * d) * UG)
    assert dtheta.mean(axis=0) * RATE == pytest.approx(gyro, rel=1e-12, abs=1e-15)
    assert dv.mean(axis=0) * RATE == pytest.approx(accel, rel=1e-12, abs=1e-12)
    assert (dv.mean(axis=0) * RATE - specific_force)[0] / UG == pytest.approx(10.0 * 45 + 0.5 * 45 ** 2)


def test_the_emulated_world_holds_the_chamber_at_its_set_point(tmp_path):
    cfg_path = tmp_path / "c.yaml"
    data = yaml.safe_load(open("configs/emulated_swing.yaml"))
    data.setdefault("imu", {}).setdefault("errors", {}).update({"temperature_c": 20.0, "thermal": THERMAL})
    data["environment"] = {"chamber": {"source": "emulator", "set_point_c": -20.0}}
    cfg_path.write_text(yaml.safe_dump(data))
    _, errors = emulated_world(load_config(cfg_path))
    assert errors.temperature_c(np.array([0.0, 600.0])) == pytest.approx([20.0, -20.0 + 40.0 / math.e])


def test_the_sensor_follows_the_emulated_chamber_after_a_set_point_written_over_modbus():
    """Two first-order lags in cascade, the chamber's air (600 s, not ramp-limited) and the case (100 s), after
    a 10 deg C step: T(t) = 35 - 10 (600 exp(-t/600) - 100 exp(-t/100)) / 500."""
    from drivers.watlow_f4 import WatlowF4
    from emulators.chamber import emulated_chamber
    from hil.config_environment import ChamberConfig

    chamber = emulated_chamber(ChamberConfig(source="emulator", set_point_c=25.0, tau_s=600.0, ramp_c_per_min_max=2.0))
    model = SensorErrorModel(ImuErrors(temperature_c=25.0, thermal={**THERMAL, "case_tau_s": 100.0}), 10.0, 1)
    model.follow_chamber(chamber.air_at)
    driver = WatlowF4(chamber.path).open()
    try:
        driver.set_set_point_c(35.0)
        seen = [model.temperature_c(np.arange(1, 11) / 10.0 + s)[-1] for s in range(300)]
        assert driver.temperature_c() == pytest.approx(35.0 - 10.0 * math.exp(-0.5), abs=0.05)  # one decimal
    finally:
        driver.close()
        chamber.close()
    expected = 35.0 - 10.0 * (600.0 * math.exp(-0.5) - 100.0 * math.exp(-3.0)) / 500.0
    assert seen[-1] == pytest.approx(expected, abs=0.02)
    assert np.all(np.diff(seen) > 0)


def test_hil_simulate_reports_the_thermal_model_temperature_in_result_json(tmp_path):
    from hil.cli import main

    data = yaml.safe_load(open("configs/emulated_swing.yaml"))
    data["trial"]["duration_s"] = 10
    data["imu"]["errors"].update({"temperature_c": 22.0, "thermal": {**THERMAL, "case_tau_s": 20.0}})
    data["environment"] = {"chamber": {"source": "emulator", "set_point_c": 40.0}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(data))
    main(["simulate", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "out"), "--no-history"])
    seen = json.loads((tmp_path / "out" / "result.json").read_text())["streams"]["imu_temperature_c"]
    rate = 200.0  # the IMU samples at trial.rate_hz
    assert seen["min"] == pytest.approx(40.0 - 18.0 * math.exp(-1.0 / rate / 20.0), abs=1e-9)
    assert seen["max"] == pytest.approx(40.0 - 18.0 * math.exp(-10.0 / 20.0), abs=1e-9)


def test_the_thermal_truth_is_the_bias_and_scale_factor_the_emulated_imu_has_at_its_temperature():
    """calibration.json's ``truth.thermal.terms`` against the emulated IMU itself, soaked at 70 deg C with static
    scale factors and biases: the thermal errors act on the ideal increments, ahead of the triad's scale factor, so
    each thermal coefficient is seen times 1 + S (0.027 ppm of gyro z's scale factor and 0.054 ug of accelerometer
    z's bias here, about two sigma of the quick thermal calibration's first-order coefficients)."""
    from hil.outputs.calibration_thermal import thermal_truth

    statics = {"accel_bias_ug": [60.0, 150.0, 260.0], "accel_scale_ppm": [120.0, -250.0, 300.0],
               "gyro_bias_dph": [0.5, -0.3, 0.8], "gyro_scale_ppm": [50.0, -80.0, 150.0]}
    errors = ImuErrors(temperature_c=70.0, thermal=THERMAL, **statics)
    model = SensorErrorModel(errors, RATE, 1, 70.0)
    n, rate, force = 10, np.array([0.5, -1.0, 2.0]), np.array([3.0, -4.0, 9.8])
    seen = []
    for k, sign in enumerate((1.0, -1.0)):
        t = (np.arange(1, n + 1) + k * n) / RATE
        dtheta, dv = model.apply(t, np.tile(sign * rate / RATE, (n, 1)), np.tile(sign * force / RATE, (n, 1)))
        seen.append((dtheta.mean(axis=0) * RATE, dv.mean(axis=0) * RATE))
    (gyro_up, accel_up), (gyro_down, accel_down) = seen
    measured = {"gyro.scale_ppm": ((gyro_up - gyro_down) / (2 * rate) - 1.0) / 1e-6,
                "gyro.bias_dph": (gyro_up + gyro_down) / 2 / DEG_PER_H,
                "accel.scale_ppm": ((accel_up - accel_down) / (2 * force) - 1.0) / 1e-6,
                "accel.bias_ug": (accel_up + accel_down) / 2 / UG}
    _, truth = thermal_truth(errors, (0.0, 0.0, 0.0), 40.0, 2)
    for key, values in measured.items():
        at_70 = [np.polyval(truth["terms"][f"{key}.{i}"][::-1], 30.0) for i in range(3)]
        assert values == pytest.approx(at_70, rel=1e-9, abs=1e-7), key
