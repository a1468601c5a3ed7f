"""Multi-position calibration: schedule geometry, recovery of every term, sigma consistency over seeds,
unobservable terms, the emulator's error model inverted, the calibration file."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from emulators.motion import ConstantRate
from emulators.sensor_errors import SensorErrorModel
from emulators.truth import Truth
from hil.config import CalibrationConfig, ImuErrors, LimitsConfig
from hil.estimation.accel_calibration import (
    calibrate_accelerometers,
    magnitude_jacobian,
)
from hil.estimation.calibration_model import (
    INDEX,
    TERMS,
    Window,
    compensate,
    fold_inner_rotation,
    forward,
    inverse,
    window_from_samples,
)
from hil.estimation.calibration_schedule import (
    Dwell,
    Plateau,
    Schedule,
    check_limits,
    default_schedule,
    schedule_duration,
    schedule_from_config,
)
from hil.estimation.gyro_calibration import calibrate_gyros
from hil.frames import EARTH_RATE, Earth, TableGeometry
from hil.outputs.calibration import calibration_document, write_calibration
from hil.pipeline.compensation import CalibrationFileError, load_calibration
from hil.units import ARCSEC, DEG, DEG_PER_H, G0, PPM, UG

LATITUDE = 39.9 * DEG
EARTH = Earth(LATITUDE, 50.0)
GEOMETRY = TableGeometry()
RATE_HZ = 200.0
UNITS = np.array([UG] * 3 + [PPM] * 3 + [ARCSEC] * 6 + [UG / G0**2] * 3 + [ARCSEC] * 3)

ACCEL = {"bias": np.array([60.0, 150.0, 260.0]) * UG, "scale": np.array([120.0, -250.0, 300.0]) * PPM,
             "mis": np.array([12.0, -20.0, 30.0, 15.0, -25.0, 8.0]) * ARCSEC,
             "knl": np.array([20.0, -30.0, 40.0]) * UG / G0**2}
GYRO = {"bias": np.array([0.02, -0.03, 0.05]) * DEG_PER_H, "scale": np.array([50.0, -80.0, 150.0]) * PPM,
            "mis": np.array([-10.0, 6.0, 14.0, -9.0, 22.0, -5.0]) * ARCSEC, "knl": np.zeros(3)}
ZERO = np.array([35.0, 30.0, -20.0]) * ARCSEC  # true gimbal angle minus encoder, (outer, middle, inner)


# --- an independent statement of the model (the 2018 paper's Eq. (6) with the emulator's signs) -------------

def paper_c_pa(xy, xz, yx, yz, zx, zy):
    """Eq. (5): rows are the sensitive axes; axis i turned by beta_ij about platform axis j."""
    return np.array([[1.0, xz, -xy], [-yz, 1.0, yx], [zy, -zx, 1.0]])


def body_from_n(angles):
    """C_n^b of Rz(outer) Rx(middle) Ry(inner), scipy's intrinsic ZXY."""
    return Rotation.from_euler("ZXY", angles).inv().as_matrix()


def sensor(truth_force, errors, noise, rng, samples):
    v = np.diag(1.0 + errors["scale"]) @ paper_c_pa(*errors["mis"]) @ truth_force
    return v + errors["knl"] * v**2 + errors["bias"] + rng.normal(0.0, noise / math.sqrt(samples), 3)


def earth_rate_n():
    return EARTH_RATE * np.array([0.0, math.cos(LATITUDE), math.sin(LATITUDE)])


def gimbal_rate_body(angles, rates):
    """omega_nb^b: each gimbal's axis carried into the body by the gimbals inside it."""
    inner = Rotation.from_euler("Y", angles[2]).inv()
    middle = Rotation.from_euler("X", angles[1]).inv()
    return inner.apply(middle.apply([0, 0, rates[0]]) + [rates[1], 0, 0]) + [0, rates[2], 0]


def synthetic_windows(schedule, accel, gyro, zero, accel_noise, gyro_noise, rng, rows=24):
    g = EARTH.g
    windows = []
    for d in schedule.dwells:
        n = int(d.dwell_s * RATE_HZ)
        c = body_from_n(np.array(d.angles) + zero)
        f = sensor(c @ [0.0, 0.0, g], accel, accel_noise, rng, n)
        w = sensor(c @ earth_rate_n(), gyro, gyro_noise, rng, n)
        windows.append(Window(np.array([d.angles]), np.zeros(3), f, w, n, d.dwell_s))
    for p in schedule.plateaus:
        n = int(p.duration_s * RATE_HZ)
        rates = np.zeros(3)
        rates[p.axis] = p.rate
        t = (np.arange(rows) + 0.5) / rows * p.duration_s
        encoder = np.array(p.angles) + np.outer(t, rates)
        omega = np.mean([body_from_n(a + zero) @ earth_rate_n() + gimbal_rate_body(a + zero, rates)
                         for a in encoder], axis=0)
        w = sensor(omega, gyro, gyro_noise, rng, n)
        windows.append(Window(encoder, rates, np.full(3, np.nan), w, n, p.duration_s))
    return windows


def theta(errors, zero):
    return np.concatenate([errors["bias"], errors["scale"], errors["mis"], errors["knl"], zero])


def absorbed(errors, zero):
    """What the schedule can see: the inner zero offset is a turn of the whole triad about the inner axis
    (y), so the fit finds K' = (I + S) C Ry(-inner zero) with the inner zero taken as zero; theta of K'."""
    k = np.diag(1.0 + errors["scale"]) @ paper_c_pa(*errors["mis"]) @ Rotation.from_euler("Y", -zero[2]).as_matrix()
    scale = np.diag(k) - 1.0
    c = k / (1.0 + scale)[:, None]
    mis = np.array([-c[0, 2], c[0, 1], c[1, 2], -c[1, 0], -c[2, 1], c[2, 0]])
    return theta({**errors, "scale": scale, "mis": mis}, np.array([zero[0], zero[1], 0.0]))


def run(schedule, seed=0, accel_noise=50 * UG, gyro_noise=0.01 * DEG_PER_H, zero=ZERO, accel=ACCEL, gyro=GYRO):
    rng = np.random.default_rng(seed)
    windows = synthetic_windows(schedule, accel, gyro, zero, accel_noise, gyro_noise, rng)
    acc = calibrate_accelerometers(windows, EARTH, GEOMETRY)
    gyr = calibrate_gyros(windows, EARTH, GEOMETRY, acc.refined.theta[15:18], acc.refined.covariance[15:18, 15:18])
    return windows, acc, gyr


ACCEL_OBSERVED = [t for t in TERMS if t not in ("zero_offset_outer", "zero_offset_inner")]
GYRO_OBSERVED = [t for t in TERMS[:12]] + ["zero_offset_outer"]


# --- schedule ---------------------------------------------------------------------------------------------

def test_eighteen_positions_put_each_axis_up_and_down_then_one_horizontal_two_at_45_degrees():
    angles = np.array([d.angles for d in default_schedule().dwells])
    up = np.array([body_from_n(a) @ [0.0, 0.0, 1.0] for a in angles])
    assert len(up) == 18 and len({tuple(np.round(u, 9)) for u in up}) == 18
    first, rest = up[:6], up[6:]
    assert sorted(map(tuple, np.round(first, 12) + 0.0)) == sorted(
        map(tuple, np.vstack([np.eye(3), -np.eye(3)])))
    for u in rest:
        tilt = np.degrees(np.arccos(np.clip(np.abs(u), 0, 1)))
        assert sorted(np.round(tilt, 9)) == [45.0, 45.0, 90.0]
    assert sorted(np.flatnonzero(np.abs(u) < 1e-12)[0] for u in rest) == [0] * 4 + [1] * 4 + [2] * 4


def test_plateaus_turn_each_axis_both_ways_within_the_limits():
    schedule = default_schedule()
    assert sorted((p.axis, np.sign(p.rate)) for p in schedule.plateaus) == [
        (a, s) for a in range(3) for s in (-1.0, 1.0)]
    check_limits(schedule, LimitsConfig())


def test_schedule_outside_the_table_limits_is_refused_naming_the_step():
    schedule = Schedule((Dwell((0.0, 0.0, 0.0), 20.0, 2.0), Dwell((0.0, 95 * DEG, 0.0), 20.0, 2.0)))
    with pytest.raises(ValueError, match="position 2: middle angle 95 deg is outside"):
        check_limits(schedule, LimitsConfig())
    fast = Schedule((), (Plateau((0.0, 0.0, 0.0), 0, 150 * DEG, 10.0, 1.0),))
    with pytest.raises(ValueError, match="plateau 1: outer rate 150 deg/s exceeds"):
        check_limits(fast, LimitsConfig())


def test_schedule_from_config_lists_positions_in_degrees():
    schedule = schedule_from_config(CalibrationConfig(positions=[(0, 45, 90), (10, 0, 0)], dwell_s=5))
    assert np.allclose(schedule.dwells[0].angles, np.array([0, 45, 90]) * DEG)
    assert [d.dwell_s for d in schedule.dwells] == [5, 5] and len(schedule.plateaus) == 6


# --- recovery ---------------------------------------------------------------------------------------------

def test_noise_free_calibration_recovers_every_term_and_reports_the_inner_and_outer_zero_offsets():
    _, acc, gyr = run(default_schedule(), accel_noise=0.0, gyro_noise=0.0)
    expected = absorbed(ACCEL, ZERO)
    for name in ACCEL_OBSERVED:
        k = INDEX[name]
        assert abs(acc.refined.theta[k] - expected[k]) <= 1e-6 * abs(expected[k]), name
    assert "misalignment_xy" in acc.refined.unobservable["zero_offset_inner"]
    assert "misalignment_zy" in acc.refined.unobservable["zero_offset_inner"]
    assert "vertical" in acc.refined.unobservable["zero_offset_outer"]
    expected = absorbed(GYRO, ZERO)
    for name in GYRO_OBSERVED:
        k = INDEX[name]
        assert abs(gyr.theta[k] - expected[k]) <= 1e-6 * abs(expected[k]), name


def test_zero_errors_give_zero_within_numerical_noise():
    none = {"bias": np.zeros(3), "scale": np.zeros(3), "mis": np.zeros(6), "knl": np.zeros(3)}
    _, acc, gyr = run(default_schedule(), accel_noise=0.0, gyro_noise=0.0, zero=np.zeros(3), accel=none, gyro=none)
    assert np.nanmax(np.abs(acc.refined.theta / UNITS)) < 1e-6  # ug, ppm, arcsec, ug/g^2
    assert np.nanmax(np.abs(gyr.theta[:12] / UNITS[:12])) < 1e-6


def test_the_fine_stage_separates_nonlinearity_from_bias():
    strong = {**ACCEL, "knl": np.array([60.0, -50.0, 80.0]) * UG / G0**2}
    _, acc, _ = run(default_schedule(plateau_s=36.0), accel_noise=0.0, gyro_noise=0.0, accel=strong)
    coarse_error = np.abs(acc.coarse.theta[0:3] - strong["bias"]) / UG
    fine_error = np.abs(acc.fine.theta[0:3] - strong["bias"]) / UG
    refined_error = np.abs(acc.refined.theta[0:3] - strong["bias"]) / UG
    assert np.all(coarse_error > 5.0)
    assert np.all(fine_error < 1e-3) and np.all(refined_error < 1e-3)
    assert np.allclose(acc.fine.theta[12:15], strong["knl"], rtol=1e-5)


def test_reported_sigma_is_the_error_the_calibration_makes_over_seeds():
    schedule = default_schedule(plateau_s=20.0)
    errors, sigmas = [], []
    for seed in range(20):
        _, acc, gyr = run(schedule, seed=seed)
        a = [INDEX[t] for t in ACCEL_OBSERVED]
        g = [INDEX[t] for t in GYRO_OBSERVED]
        errors.append(np.concatenate([(acc.refined.theta - absorbed(ACCEL, ZERO))[a],
                                      (gyr.theta - absorbed(GYRO, ZERO))[g]]))
        sigmas.append(np.concatenate([acc.refined.sigma[a], gyr.sigma[g]]))
    errors, sigmas = np.array(errors), np.array(sigmas)
    ratio = np.sqrt(np.mean(errors**2, axis=0)) / np.mean(sigmas, axis=0)
    assert 0.85 < np.sqrt(np.mean(ratio**2)) < 1.15, ratio
    assert np.all((ratio > 0.55) & (ratio < 1.6)), ratio
    assert np.mean(np.abs(errors) < 3 * sigmas) >= 0.95


def sampled_windows(schedule, rng, accel_noise=50 * UG, gyro_noise=0.01 * DEG_PER_H):
    """The windows of :func:`synthetic_windows` built as a trial builds them, from every sample's increments
    (white noise on each sample), so that each window also measures its noise."""
    windows = []
    for w in synthetic_windows(schedule, ACCEL, GYRO, ZERO, 0.0, 0.0, rng):
        n = w.samples
        dt = np.full(n, w.duration_s / n)
        force = np.nan_to_num(w.specific_force) + rng.normal(0.0, accel_noise, (n, 3))
        rate = w.angular_rate + rng.normal(0.0, gyro_noise, (n, 3))
        windows.append(window_from_samples(rate * dt[:, None], force * dt[:, None], dt, w.angles, w.rates))
    return windows


def test_with_the_noise_measured_in_the_windows_the_errors_over_sigmas_are_normal_to_the_tails():
    """18 windows and some 16 terms leave about a dozen degrees of freedom to a noise estimate from the
    residuals alone, and the errors over such sigmas follow Student's t, whose tails are heavy: with 29 terms
    a "4 sigma" bound fails some 4 % of calibrations. Each sample's variance, measured inside its window
    (hundreds of samples), makes them normal; the residuals may only inflate it. Over 120 seeds and 29
    terms (3480 values) a normal gives 9.4 beyond 3 sigma (99th percentile 17); the residual-only sigmas give
    23 on these seeds."""
    schedule = default_schedule(dwell_s=4.0, plateau_s=10.0)
    a, g = [INDEX[t] for t in ACCEL_OBSERVED], [INDEX[t] for t in GYRO_OBSERVED]
    z = []
    for seed in range(120):
        windows = sampled_windows(schedule, np.random.default_rng(1000 + seed))
        acc = calibrate_accelerometers(windows, EARTH, GEOMETRY)
        gyr = calibrate_gyros(windows, EARTH, GEOMETRY, acc.refined.theta[15:18],
                              acc.refined.covariance[15:18, 15:18])
        z.append(np.concatenate([(acc.refined.theta - absorbed(ACCEL, ZERO))[a] / acc.refined.sigma[a],
                                 (gyr.theta - absorbed(GYRO, ZERO))[g] / gyr.sigma[g]]))
    z = np.abs(np.array(z))
    assert np.count_nonzero(z > 3) <= 17 and z.max() < 4.5, (np.count_nonzero(z > 3), z.max())
    accel_rms = np.sqrt(np.mean(z[:, :len(a)] ** 2, axis=0))  # the gyro's sigmas are larger than its errors
    assert 0.8 < np.sqrt(np.mean(accel_rms**2)) < 1.15, accel_rms


def test_six_positions_cannot_give_the_middle_zero_offset_nor_the_magnitude_stage_nonlinearity():
    _, acc, _ = run(default_schedule(positions=6), accel_noise=0.0, gyro_noise=0.0)
    reason = acc.refined.unobservable["zero_offset_middle"]
    assert "nonlinearity_y" in reason and "bias_y" in reason
    assert {"nonlinearity_x", "nonlinearity_y", "nonlinearity_z"} <= set(acc.fine.unobservable)
    assert set(acc.refined.unobservable) == {"zero_offset_middle", "zero_offset_inner", "zero_offset_outer"}


def test_magnitude_jacobian_matches_finite_differences():
    rng = np.random.default_rng(4)
    theta0 = np.concatenate([rng.normal(0, 1e-3, 12), rng.normal(0, 1e-4, 3), np.zeros(3)])
    y = rng.normal(0.0, 6.0, (5, 3))
    def half_square(th):
        return 0.5 * np.sum(inverse(th, y) ** 2, axis=1)
    numeric = np.empty((5, 18))
    for k in range(18):
        step = np.zeros(18)
        step[k] = 1e-7
        numeric[:, k] = (half_square(theta0 + step) - half_square(theta0 - step)) / 2e-7
    assert np.allclose(magnitude_jacobian(theta0, y), numeric, rtol=1e-6, atol=1e-6)


def test_compensation_inverts_the_model():
    rng = np.random.default_rng(5)
    a, g = theta(ACCEL, np.zeros(3)), theta(GYRO, np.zeros(3))
    f, w = rng.normal(0, 9.0, (10, 3)), rng.normal(0, 1.0, (10, 3))
    dt = 1.0 / RATE_HZ
    dtheta, dv = compensate(a, g, forward(g, w) * dt, forward(a, f) * dt, dt)
    assert np.allclose(dv, f * dt, rtol=0, atol=1e-15) and np.allclose(dtheta, w * dt, rtol=0, atol=1e-16)


def test_folding_the_inner_zero_offset_gives_what_the_schedule_sees():
    for errors in (ACCEL, GYRO):
        assert np.allclose(fold_inner_rotation(theta(errors, ZERO), ZERO[2]), absorbed(errors, ZERO), rtol=0, atol=1e-15)


def test_a_mounted_triad_sees_the_inner_zero_offset_as_a_turn_about_its_own_axis_along_the_inner_gimbal():
    """Mounted by M (body to mount), the inner gimbal's axis is M^T y in the triad's axes: the zero offset is a turn
    of -zero about that axis, K' = (I + S) C R(-zero, M^T y)."""
    mounting = Rotation.from_euler("ZYX", [90.0, 0.0, 180.0], degrees=True).as_matrix()
    for errors in (ACCEL, GYRO):
        turn = Rotation.from_rotvec(-ZERO[2] * (mounting.T @ np.array([0.0, 1.0, 0.0]))).as_matrix()
        k = np.diag(1.0 + errors["scale"]) @ paper_c_pa(*errors["mis"]) @ turn
        scale = np.diag(k) - 1.0
        c = k / (1.0 + scale)[:, None]
        mis = np.array([-c[0, 2], c[0, 1], c[1, 2], -c[1, 0], -c[2, 1], c[2, 0]])
        expected = theta({**errors, "scale": scale, "mis": mis}, np.array([ZERO[0], ZERO[1], 0.0]))
        assert np.allclose(fold_inner_rotation(theta(errors, ZERO), ZERO[2], mounting), expected, rtol=0, atol=1e-15)


def test_schedule_duration_adds_moves_at_the_limits_settling_and_windows():
    limits = LimitsConfig(rate_dps=(10, 10, 10), accel_dps2=(10, 10, 10))
    # a 90 deg inner move: 1 s ramps, 8 s cruising = 10 s, + 0.5 s arrival + 2 s settle + 20 s dwell
    schedule = Schedule((Dwell((0.0, 0.0, 90 * DEG), 20.0, 2.0),))
    assert schedule_duration(schedule, limits) == pytest.approx(32.5)
    # then a 10 deg/s outer plateau from the zero position: 10 s back, 1 s ramp, arrival twice, settle, 30 s
    schedule = Schedule(schedule.dwells, (Plateau((0.0, 0.0, 0.0), 0, 10 * DEG, 30.0, 2.0),))
    assert schedule_duration(schedule, limits) == pytest.approx(32.5 + 10.0 + 0.5 + 2.0 + 1.0 + 0.5 + 30.0)


# --- the emulator's forward model, inverted ------------------------------------------------------------

def test_calibration_recovers_the_errors_the_emulator_applies():
    errors = ImuErrors(accel_bias_ug=(60, 150, 260), accel_scale_ppm=(120, -250, 300),
                       accel_misalignment_arcsec=(12, -20, 30, 15, -25, 8),
                       accel_nonlinearity_ug_per_g2=(20, -30, 40),
                       gyro_bias_dph=(0.02, -0.03, 0.05), gyro_scale_ppm=(50, -80, 150),
                       gyro_misalignment_arcsec=(-10, 6, 14, -9, 22, -5))
    zero = np.array([0.0, 30.0, 0.0]) * ARCSEC
    model = SensorErrorModel(errors, RATE_HZ, seed=1)
    schedule = default_schedule(dwell_s=1.0, plateau_s=3.0, rate=30 * DEG)
    windows, t0 = [], 0.0
    for step in list(schedule.dwells) + list(schedule.plateaus):
        rates = np.zeros(3)
        if isinstance(step, Plateau):
            rates[step.axis] = step.rate
        length = step.dwell_s if isinstance(step, Dwell) else step.duration_s
        t = t0 + np.arange(1, int(length * RATE_HZ) + 1) / RATE_HZ
        truth = Truth(EARTH, GEOMETRY, ConstantRate(np.array(step.angles) + zero - rates * t0, rates))
        dtheta, dv = model.apply(t, *truth.increments(t0, t))
        encoder = truth.angles(t - 0.5 / RATE_HZ) - zero  # at the midpoints of the intervals
        windows.append(window_from_samples(dtheta, dv, np.full(len(t), 1.0 / RATE_HZ), encoder, rates))
        t0 = t[-1]
    acc = calibrate_accelerometers(windows, EARTH, GEOMETRY)
    gyr = calibrate_gyros(windows, EARTH, GEOMETRY, zero_offsets=acc.refined.theta[15:18])
    doc = calibration_document(acc, gyr, windows, truth=errors)
    for block in ("accel", "gyro"):
        for key, estimate in doc[block].items():
            assert np.allclose(estimate, doc["truth"][block][key], rtol=1e-3, atol=1e-6), (block, key)
    assert doc["turntable"]["zero_offset_arcsec"][1] == pytest.approx(30.0, rel=1e-3)
    assert doc["turntable"]["zero_offset_arcsec"][0] == pytest.approx(0.0, abs=1e-3)
    assert doc["turntable"]["zero_offset_arcsec"][2] is None
    assert "turntable.zero_offset_arcsec.2" in doc["unobservable"]


# --- the calibration file ---------------------------------------------------------------------------------

def test_calibration_file_round_trips_to_the_fitted_model(tmp_path):
    windows, acc, gyr = run(default_schedule(), accel_noise=0.0, gyro_noise=0.0, zero=np.zeros(3))
    path = tmp_path / "calibration.json"
    write_calibration(path, calibration_document(acc, gyr, windows))
    accel, gyro = load_calibration(path)
    keep = slice(0, 15)
    assert np.allclose(accel[keep], acc.refined.theta[keep], rtol=1e-12, atol=1e-18)
    assert np.allclose(gyro[:12], gyr.theta[:12], rtol=1e-12, atol=1e-18)
    doc = json.loads(path.read_text())
    assert [len(p["residual_ug"]) for p in doc["positions"]] == [3] * 18


@pytest.mark.parametrize(("change", "message"), [
    ({"accel": {"bias_ug": [1, 2]}}, r"accel.bias_ug: expected a list of 3 numbers or nulls, got 2"),
    ({"accel": {"bias_mg": [1, 2, 3]}}, r"accel.bias_mg: unknown key"),
    ({"gyro": {"scale_ppm": [1, "a", 3]}}, r"gyro.scale_ppm\[1\]: expected a finite number"),
])
def test_a_calibration_file_with_wrong_keys_is_one_line_naming_the_key(tmp_path, change, message):
    good = {"accel": {"bias_ug": [0, 0, 0], "scale_ppm": [0, 0, 0], "misalignment_arcsec": [0] * 6,
                      "nonlinearity_ug_per_g2": [0, 0, 0]},
            "gyro": {"bias_dph": [0, 0, 0], "scale_ppm": [0, 0, 0], "misalignment_arcsec": [0] * 6}}
    for block, keys in change.items():
        good[block] = {**good[block], **keys}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(good))
    with pytest.raises(CalibrationFileError, match=message) as info:
        load_calibration(path)
    assert "\n" not in str(info.value)
