import math

import numpy as np
import pytest
from tests.helpers import earth_turn, scipy_attitude
from scipy.spatial.transform import Rotation

from hil.frames import (
    EARTH_RATE,
    EULER_SEQ,
    Earth,
    TableGeometry,
    euler_from_matrix,
    euler_matrix,
    normal_gravity,
    rotation_vector_matrix,
    table_body_rotation,
)


def rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.mark.parametrize(
    "lat_deg, expected",
    [(0.0, 9.7803253359), (90.0, 9.8321849378), (-90.0, 9.8321849378)],  # WGS-84 equatorial and polar gravity
)
def test_normal_gravity_matches_published_wgs84_values(lat_deg, expected):
    assert normal_gravity(math.radians(lat_deg)) == pytest.approx(expected, abs=2e-9)


def test_free_air_gradient_is_about_3086_ugal_per_m():
    lat = math.radians(32)
    gradient = (normal_gravity(lat, 0.0) - normal_gravity(lat, 100.0)) / 100.0
    assert gradient == pytest.approx(3.086e-6, rel=2e-3)


def test_earth_rate_in_enu():
    earth = Earth.from_degrees(32.0)
    np.testing.assert_allclose(
        earth.omega_n, EARTH_RATE * np.array([0, math.cos(math.radians(32)), math.sin(math.radians(32))])
    )


def test_gimbal_attitude_is_rz_rx_ry_product():
    angles = np.array([0.3, -0.2, 0.7])  # outer, middle, inner
    c = TableGeometry().attitude_matrix(angles)[0][0]
    np.testing.assert_allclose(c, rz(0.3) @ rx(-0.2) @ ry(0.7), atol=1e-15)


def test_table_azimuth_tilt_and_mounting_compose_in_documented_order():
    geo = TableGeometry(azimuth=0.1, tilt=(1e-3, -2e-3), mounting=(0.02, 0.01, -0.03))
    angles = np.array([0.3, -0.2, 0.7])
    tilt = Rotation.from_rotvec([1e-3, -2e-3, 0]).as_matrix()
    mount = rz(0.02) @ rx(0.01) @ ry(-0.03)
    expected = tilt @ rz(0.1) @ rz(0.3) @ rx(-0.2) @ ry(0.7) @ mount
    np.testing.assert_allclose(geo.attitude_matrix(angles)[0][0], expected, atol=1e-15)
    np.testing.assert_allclose(scipy_attitude(geo, angles).as_matrix(), expected, atol=1e-15)


def test_rotation_vector_matrix_is_scipys():
    rng = np.random.default_rng(4)
    for v in [*rng.normal(0.0, 1.0, (5, 3)), *rng.normal(0.0, 1e-9, (3, 3)), np.zeros(3), np.array([0.0, 0.0, math.pi])]:
        np.testing.assert_allclose(rotation_vector_matrix(v), Rotation.from_rotvec(v).as_matrix(), rtol=0, atol=4e-16)


def test_euler_angles_round_trip():
    ypr = np.array([[0.1, 0.2, -0.3], [2.0, -0.5, 1.0]])
    np.testing.assert_allclose(Rotation.from_matrix(euler_matrix(ypr)).as_euler(EULER_SEQ), ypr, atol=1e-14)
    np.testing.assert_allclose(euler_matrix(ypr), Rotation.from_euler(EULER_SEQ, ypr).as_matrix(), rtol=0, atol=4e-16)
    np.testing.assert_array_equal(euler_matrix(ypr[1]), euler_matrix(ypr)[1])
    for row in ypr:
        np.testing.assert_allclose(euler_from_matrix(rz(row[0]) @ rx(row[1]) @ ry(row[2])), row, atol=1e-14)


def test_body_rate_matches_finite_difference_of_attitude():
    geo = TableGeometry(azimuth=0.2, tilt=(1e-3, 0.0), mounting=(0.05, -0.02, 0.03))
    t = 0.37
    def angles(t):
        return np.array([0.3 * math.sin(t), 0.2 * math.cos(1.3 * t), 0.5 * math.sin(0.7 * t + 1)])
    def rates(t):
        return np.array([0.3 * math.cos(t), -0.26 * math.sin(1.3 * t), 0.35 * math.cos(0.7 * t + 1)])
    h = 1e-6
    c_minus, c_plus, c = (scipy_attitude(geo, angles(s)).as_matrix() for s in (t - h, t + h, t))
    skew = c.T @ (c_plus - c_minus) / (2 * h)  # C^T dC/dt = [omega x]
    expected = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
    _, middle_inner, inner = geo.attitude_matrix(angles(t))
    np.testing.assert_allclose(geo.body_rate_from(middle_inner, inner, rates(t))[0], expected, atol=1e-9)


def test_earth_turn_matrices_are_scipys_rotation_about_the_earth_axis():
    earth = Earth.from_degrees(32.0)
    t = np.array([0.0, 1e-3, 0.005, 3600.0, 43082.0])  # up to half a sidereal day
    np.testing.assert_allclose(earth.turn_matrices(t), earth_turn(earth, t).as_matrix(), rtol=0, atol=2e-16)


def test_table_body_rotation_is_the_composition_of_the_attitudes_and_the_earth_turn():
    """C_n^b(t1) C_n(t2)^n(t1) C_b^n(t2), formed with scipy rotations."""
    geo = TableGeometry(azimuth=0.2, tilt=(1e-3, 0.0), mounting=(0.05, -0.02, 0.03))
    earth = Earth.from_degrees(32.0)
    rng = np.random.default_rng(3)
    start = rng.uniform(-math.pi, math.pi, (20, 3))
    end = start + rng.normal(0.0, 0.01, (20, 3))
    dt = rng.uniform(1e-3, 1.0, 20)
    expected = (scipy_attitude(geo, start).inv() * earth_turn(earth, dt) * scipy_attitude(geo, end)).as_matrix()
    np.testing.assert_allclose(table_body_rotation(geo, earth, dt, start, end), expected, rtol=0, atol=1e-14)
