import math

import numpy as np
import pytest
from tests.helpers import true_attitude_ib0
from scipy.spatial.transform import Rotation

from emulators.motion import Positions, motion_from_config
from emulators.truth import Truth
from hil.estimation.strapdown import Strapdown
from hil.frames import EARTH_RATE, Earth, TableGeometry
from hil.units import DEG
from tests.helpers import make_config


def test_integrated_ideal_increments_reproduce_true_attitude_after_one_hour():
    cfg = make_config(duration=3600, rate=200)
    truth = Truth(Earth.from_degrees(32), TableGeometry(), motion_from_config(cfg.turntable.motion))
    rate, chunk = 200.0, 72000
    strapdown = Strapdown()
    for start in range(0, 720000, chunk):
        t = np.arange(start + 1, start + chunk + 1) / rate
        dtheta, dv = truth.increments(start / rate, t)
        strapdown.update_many(dtheta, dv, np.full(chunk, 1 / rate))
    reference = true_attitude_ib0(truth, np.array([3600.0]))
    error = (reference.inv() * Rotation.from_matrix(strapdown.attitude)).magnitude()[0]
    assert error < 1e-9


def test_static_level_table_senses_gravity_and_earth_rate_exactly():
    cfg = make_config(kind="static", turntable={"motion": {"kind": "static"}})
    earth = Earth.from_degrees(32, 0.0)
    truth = Truth(earth, TableGeometry(), motion_from_config(cfg.turntable.motion))
    dtheta, dv = truth.increments(0.0, np.array([0.01, 0.02]))
    np.testing.assert_allclose(dv, [[0, 0, earth.g * 0.01]] * 2, atol=1e-15)
    np.testing.assert_allclose(dtheta, [earth.omega_n * 0.01] * 2, atol=1e-18)


def test_increments_of_a_constant_rate_about_one_axis_are_rate_times_interval():
    cfg = make_config(turntable={"motion": {"kind": "rate", "axes": {"outer": {"rate_dps": 10}}}})
    earth = Earth(math.pi / 2, 0.0)  # at the pole the earth rate is along the outer axis too
    truth = Truth(earth, TableGeometry(), motion_from_config(cfg.turntable.motion))
    dtheta, _ = truth.increments(0.0, np.array([0.005]))
    expected = np.array([0.0, 0.0, (10 * DEG + EARTH_RATE) * 0.005])
    np.testing.assert_allclose(dtheta[0], expected, atol=1e-18)


def test_swing_rates_are_the_derivative_of_the_angles():
    profile = motion_from_config(make_config().turntable.motion)
    t = np.array([1.3, 7.7])
    h = 1e-6
    numeric = (profile(t + h)[0] - profile(t - h)[0]) / (2 * h)
    np.testing.assert_allclose(profile(t)[1], numeric, atol=1e-9)


def test_positions_profile_respects_rate_and_acceleration_limits_and_reaches_targets():
    targets = np.array([[0, 0, 0], [90, -30, 45], [90, -30, 46]]) * DEG
    profile = Positions(targets, np.array([1.0, 5.0, 2.0]), rate_limit=20 * DEG, accel_limit=10 * DEG)
    t = np.arange(0, 30, 1e-3)
    angles, rates = profile(t)
    assert np.max(np.abs(rates)) <= 20 * DEG * (1 + 1e-12)
    accel = np.diff(rates, axis=0) / 1e-3
    assert np.max(np.abs(accel)) <= 10 * DEG * (1 + 1e-6)
    np.testing.assert_allclose(angles[-1], targets[-1], atol=1e-12)
    move1 = profile.segments()[0]
    # 90 deg at 20 deg/s and 10 deg/s^2: 2 s ramp up, 2.5 s cruise, 2 s ramp down
    assert move1[2] == pytest.approx(2 + 2.5 + 2)
    np.testing.assert_allclose(profile(np.array([1.0 + 6.5 + 1.0]))[0][0], targets[1], atol=1e-12)
