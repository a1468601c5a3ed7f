"""Sensor error model: each term alone against its analytic output, chunking and seeding."""

from __future__ import annotations

import numpy as np
import pytest

from emulators.sensor_errors import BiasInstability, SensorErrorModel
from hil.config import ImuErrors
from hil.units import ARCSEC, DEG_PER_H, PPM, UG

RATE = 200.0
T = 1.0 / RATE
G = 9.80665


def _model(seed: int = 7, **errors) -> SensorErrorModel:
    return SensorErrorModel(ImuErrors(**errors), RATE, seed)


def _times(n: int) -> np.ndarray:
    return np.arange(1, n + 1) * T


def _motion(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Plausible ideal increments: rates of tens of deg/s, specific force around 1 g."""
    rng = np.random.default_rng(seed)
    dtheta = rng.normal(0.0, 0.5, (n, 3)) * T
    dv = (np.array([0.1, -0.2, G]) + rng.normal(0.0, 0.5, (n, 3))) * T
    return dtheta, dv


def _zeros(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((n, 3)), np.zeros((n, 3))


ALL_TERMS = dict(
    accel_bias_ug=[60, 150, 260],
    accel_noise_ug=[50, 40, 30],
    accel_drift_ug_per_h=[5, -3, 1],
    accel_random_walk_ug_per_sqrt_h=[2, 3, 4],
    accel_bias_instability_ug=[5, 10, 15],
    accel_scale_ppm=[100, -50, 20],
    accel_misalignment_arcsec=[10, -20, 30, -40, 50, -60],
    accel_nonlinearity_ug_per_g2=[10, 20, -30],
    gyro_bias_dph=[0.01, 0.02, 0.03],
    gyro_noise_dph=[0.01, 0.01, 0.02],
    gyro_drift_dph_per_h=[0.001, 0.002, -0.003],
    gyro_random_walk_dph_per_sqrt_h=[0.001, 0.001, 0.002],
    gyro_bias_instability_dph=[0.002, 0.003, 0.004],
    gyro_scale_ppm=[5, 10, -15],
    gyro_misalignment_arcsec=[1, 2, 3, 4, 5, 6],
    dtheta_quantum_rad=1e-9,
    dv_quantum_mps=1e-6,
)


def test_zero_error_config_returns_inputs_bit_exact():
    dtheta, dv = _motion(1000)
    out_dtheta, out_dv = _model().apply(_times(1000), dtheta, dv)
    assert out_dtheta.tobytes() == dtheta.tobytes()
    assert out_dv.tobytes() == dv.tobytes()


def test_bias_adds_b_times_interval_per_sample():
    model = _model(accel_bias_ug=[60, 150, 260], gyro_bias_dph=[0.01, 0.02, 0.03])
    out_dtheta, out_dv = model.apply(_times(50), *_zeros(50))
    np.testing.assert_array_equal(out_dv, np.tile(np.array([60, 150, 260]) * UG * T, (50, 1)))
    np.testing.assert_array_equal(out_dtheta, np.tile(np.array([0.01, 0.02, 0.03]) * DEG_PER_H * T, (50, 1)))

    dtheta, dv = _motion(50)
    model = _model(accel_bias_ug=[60, 150, 260], gyro_bias_dph=[0.01, 0.02, 0.03])
    out_dtheta, out_dv = model.apply(_times(50), dtheta, dv)
    np.testing.assert_allclose(out_dv - dv, np.tile(np.array([60, 150, 260]) * UG * T, (50, 1)), rtol=1e-8)


def test_white_noise_has_per_sample_sigma_and_is_white():
    n = 100_000
    model = _model(accel_noise_ug=[50, 100, 200], gyro_noise_dph=[0.01, 0.02, 0.04])
    out_dtheta, out_dv = model.apply(_times(n), *_zeros(n))
    sigma_accel = np.array([50, 100, 200]) * UG
    sigma_gyro = np.array([0.01, 0.02, 0.04]) * DEG_PER_H
    for out, sigma in ((out_dv, sigma_accel), (out_dtheta, sigma_gyro)):
        np.testing.assert_allclose(out.std(axis=0), sigma * T, rtol=0.02)
        assert np.all(np.abs(out.mean(axis=0)) < 0.02 * sigma * T)
        for axis in range(3):
            lag1 = np.corrcoef(out[1:, axis], out[:-1, axis])[0, 1]
            assert abs(lag1) < 0.015
    # The six noise sources are mutually independent.
    corr = np.corrcoef(np.hstack([out_dtheta, out_dv]).T)
    assert np.all(np.abs(corr - np.eye(6)) < 0.015)


def test_drift_is_linear_in_time_with_slope_k():
    n = 2000
    t = _times(n)
    model = _model(
        accel_bias_ug=[10, 0, 0], accel_drift_ug_per_h=[3600, -7200, 0], gyro_drift_dph_per_h=[0, 0, 36]
    )
    out_dtheta, out_dv = model.apply(t, *_zeros(n))
    k_accel = np.array([1.0, -2.0, 0.0]) * UG  # per second
    slopes = np.polyfit(t, out_dv / T, 1)[0]
    np.testing.assert_allclose(slopes, k_accel, rtol=1e-9, atol=1e-20)
    np.testing.assert_allclose(np.polyfit(t, out_dtheta[:, 2] / T, 1)[0], 0.01 * DEG_PER_H, rtol=1e-9)
    # Exact integral of b_s + k t over [0, t_n].
    expected_sum = np.array([10 * UG, 0, 0]) * t[-1] + k_accel * t[-1] ** 2 / 2
    np.testing.assert_allclose(out_dv.sum(axis=0), expected_sum, rtol=1e-9)


def test_random_walk_variance_grows_as_q_squared_t():
    n = 400_000
    q_accel = np.array([2.0, 4.0, 8.0]) * UG / 60.0  # ug/sqrt(h) -> m/s^2/sqrt(s)
    q_gyro = np.array([0.001, 0.002, 0.004]) * DEG_PER_H / 60.0
    model = _model(
        accel_random_walk_ug_per_sqrt_h=[2, 4, 8], gyro_random_walk_dph_per_sqrt_h=[0.001, 0.002, 0.004]
    )
    out_dtheta, out_dv = model.apply(_times(n), *_zeros(n))
    for out, q in ((out_dv, q_accel), (out_dtheta, q_gyro)):
        bias = out / T
        for lag in (1, 10, 100):
            increment = bias[lag:] - bias[:-lag]
            np.testing.assert_allclose(increment.var(axis=0), q**2 * lag * T, rtol=0.08)
    # The walk starts at zero: the first sample's bias is a single step.
    assert np.all(np.abs(out_dv[0] / T) < 5 * q_accel * np.sqrt(T))


def test_scale_factor_multiplies_by_one_plus_s():
    dtheta, dv = _motion(100)
    model = _model(accel_scale_ppm=[100, -200, 300], gyro_scale_ppm=[-10, 20, 1000])
    out_dtheta, out_dv = model.apply(_times(100), dtheta, dv)
    np.testing.assert_allclose(out_dv, dv * (1 + np.array([100, -200, 300]) * PPM), rtol=1e-15)
    np.testing.assert_allclose(out_dtheta, dtheta * (1 + np.array([-10, 20, 1000]) * PPM), rtol=1e-15)


def test_misalignment_follows_the_three_stage_paper_matrix():
    angles = [10, 20, 30, 40, 50, 60]  # xy, xz, yx, yz, zx, zy
    xy, xz, yx, yz, zx, zy = (a * ARCSEC for a in angles)
    dtheta, dv = _motion(20)
    accel_scale = 1 + np.array([1000, 2000, 3000]) * PPM
    model = _model(
        accel_misalignment_arcsec=angles, gyro_misalignment_arcsec=angles, accel_scale_ppm=[1000, 2000, 3000]
    )
    out_dtheta, out_dv = model.apply(_times(20), dtheta, dv)
    for x_in, x_out, scale in ((dtheta, out_dtheta, (1, 1, 1)), (dv, out_dv, accel_scale)):
        x, y, z = x_in.T
        expected = np.column_stack([
            scale[0] * (x + xz * y - xy * z),
            scale[1] * (-yz * x + y + yx * z),
            scale[2] * (zy * x - zx * y + z),
        ])
        np.testing.assert_allclose(x_out, expected, rtol=1e-14, atol=1e-18)


def test_nonlinearity_adds_k_f_squared():
    k = [10.0, 20.0, -30.0]
    dv = np.array([[G, 0.0, 0.0], [0.0, 2 * G, 0.0], [0.0, 0.0, -G], [0.0, 0.0, 0.0]]) * T
    model = _model(accel_nonlinearity_ug_per_g2=k)
    out_dtheta, out_dv = model.apply(_times(4), np.zeros((4, 3)), dv)
    expected = dv + np.array([[10.0, 0, 0], [0, 20.0 * 4, 0], [0, 0, -30.0], [0, 0, 0]]) * UG * T
    np.testing.assert_allclose(out_dv, expected, rtol=1e-13, atol=1e-20)
    np.testing.assert_array_equal(out_dtheta, 0.0)


def test_nonlinearity_is_per_standard_g_squared_whatever_the_site():
    f = 9.7946  # m/s^2: a site's gravity, not the standard 9.80665 of the unit g (and of ug)
    _, out_dv = _model(accel_nonlinearity_ug_per_g2=[100.0, 0.0, 0.0]).apply(_times(1), np.zeros((1, 3)),
                                                                             np.array([[f * T, 0.0, 0.0]]))
    assert out_dv[0, 0] - f * T == pytest.approx(100.0 * (f / 9.80665) ** 2 * 9.80665e-6 * T, rel=1e-9)


def test_quantisation_gives_whole_quanta_and_tracks_the_input_sum():
    n = 20_000  # several remainder blocks
    dtheta, dv = _motion(n)
    q_theta, q_v = 1e-5, 1e-4
    out_dtheta, out_dv = _model(dtheta_quantum_rad=q_theta, dv_quantum_mps=q_v).apply(_times(n), dtheta, dv)
    for x_in, x_out, q in ((dtheta, out_dtheta, q_theta), (dv, out_dv, q_v)):
        counts = x_out / q
        np.testing.assert_allclose(counts, np.rint(counts), rtol=0, atol=1e-6)
        assert np.max(np.abs(np.cumsum(x_out, axis=0) - np.cumsum(x_in, axis=0))) <= q
        assert np.any(x_out != x_in)


def test_bias_instability_draws_its_own_stream_so_the_other_kinds_do_not_shift():
    n = 2000
    t, (dtheta, dv) = _times(n), _zeros(n)
    others = {"gyro_noise_dph": [0.01] * 3, "gyro_random_walk_dph_per_sqrt_h": [0.001] * 3,
              "accel_noise_ug": [50] * 3, "accel_random_walk_ug_per_sqrt_h": [2] * 3}
    without = _model(**others).apply(t, dtheta, dv)
    b_dph = [0.1, 0.2, 0.3]
    with_gyro_instability = _model(**others, gyro_bias_instability_dph=b_dph).apply(t, dtheta, dv)
    assert with_gyro_instability[1].tobytes() == without[1].tobytes()
    bias = BiasInstability(np.concatenate([np.array(b_dph) * DEG_PER_H, np.zeros(3)]), T, seed=7)(n)[:, :3]
    np.testing.assert_allclose(with_gyro_instability[0] - without[0], bias * T, rtol=1e-9, atol=0.0)


def test_bias_instability_starts_stationary_with_variance_b2_ln4_over_pi_per_process():
    """Each Gauss-Markov process starts from its stationary law, so the sum's variance holds at k = 0."""
    columns = 4000
    first = BiasInstability(np.ones(columns), T, seed=1)(1)[0]
    expected = len(BiasInstability.CORRELATION_TIMES) * np.log(4.0) / np.pi
    assert np.var(first) == pytest.approx(expected, rel=4 * np.sqrt(2.0 / columns))


def test_chunked_application_equals_whole_exactly():
    n = 10_000
    t = _times(n)
    dtheta, dv = _motion(n)
    whole = _model(**ALL_TERMS).apply(t, dtheta, dv)
    chunked_model = _model(**ALL_TERMS)
    edges = [0, 0, 1, 2, 37, 4095, 4097, 4097, 8200, 9999, n]
    parts = [chunked_model.apply(t[a:b], dtheta[a:b], dv[a:b]) for a, b in zip(edges[:-1], edges[1:])]
    for i in range(2):
        assert np.concatenate([p[i] for p in parts]).tobytes() == whole[i].tobytes()


def test_same_seed_same_output_different_seed_different():
    n = 500
    t = _times(n)
    dtheta, dv = _motion(n)
    a = SensorErrorModel(ImuErrors(**ALL_TERMS), RATE, seed=11).apply(t, dtheta, dv)
    b = SensorErrorModel(ImuErrors(**ALL_TERMS), RATE, seed=11).apply(t, dtheta, dv)
    c = SensorErrorModel(ImuErrors(**ALL_TERMS), RATE, seed=12).apply(t, dtheta, dv)
    for i in range(2):
        np.testing.assert_array_equal(a[i], b[i])
        assert not np.array_equal(a[i], c[i])


def test_mismatched_shapes_raise():
    with pytest.raises(ValueError, match="expected t"):
        _model().apply(_times(3), np.zeros((3, 3)), np.zeros((2, 3)))
