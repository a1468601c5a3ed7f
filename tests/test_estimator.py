import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hil.estimation.alignment import EarthTurn, alignment_matrix, attitude_error, theoretical_error
from hil.estimation.apparent_gravity import ApparentGravityEstimator
from hil.estimation.strapdown import cumulative_product
from hil.frames import EARTH_RATE, Earth, TableGeometry, euler_matrix
from hil.samples import AlignedBatch
from hil.units import DEG, UG
from tests.helpers import PAPER_ERRORS, earth_turn, make_config, run_estimator


def test_cumulative_product_equals_sequential_products():
    steps = Rotation.random(37, random_state=3).as_matrix()
    expected = [steps[0]]
    for m in steps[1:]:
        expected.append(expected[-1] @ m)
    prefix = cumulative_product(steps.transpose(1, 2, 0).copy())  # component-major (3, 3, N)
    np.testing.assert_allclose(prefix.transpose(2, 0, 1), np.array(expected), atol=1e-14)


def test_error_free_swing_gives_zero_bias_and_method2_level_error_after_600s():
    est = run_estimator(make_config(duration=600, rate=200), solve_period=60.0)
    final = est.snapshots[-1]
    assert final.full.observable
    assert np.max(np.abs(final.full.bias)) / UG < 0.01
    assert np.max(np.abs(final.error_method2[:2])) / DEG < 1e-6


def test_recursive_estimate_equals_batch_least_squares():
    """Feed known measurements, then solve the stacked H (2019 eq. 14, paper basis) with lstsq."""
    rng = np.random.default_rng(5)
    n = 3000
    t_end = np.arange(1, n + 1) * 1.0
    t_start = t_end - 1.0
    c = Rotation.from_rotvec(0.2 * np.sin(np.outer(t_end, [0.7, 0.9, 0.5]))).as_matrix()
    a_true = rng.normal(size=(3, 3)) * 5
    bias = np.array([60, 150, 260]) * UG
    mid = EARTH_RATE * 0.5 * (t_start + t_end)
    basis = np.column_stack((np.cos(mid), np.sin(mid), np.ones(n)))
    z = basis @ a_true.T + c @ bias + rng.normal(scale=50 * UG, size=(n, 3))
    est = ApparentGravityEstimator()
    for k in range(0, n, 700):  # uneven chunks
        est.update_many(t_start[k : k + 700], t_end[k : k + 700], z[k : k + 700], c[k : k + 700])
    solution = est.solve()
    # Independent batch solution with the interval-mean basis written out directly.
    h = 0.5 * EARTH_RATE * 1.0
    sinc = np.sin(h) / h
    mean_basis = np.column_stack((np.cos(mid) * sinc, np.sin(mid) * sinc, np.ones(n)))
    rows = np.zeros((3 * n, 12))
    for r in range(3):
        rows[r::3, 3 * r : 3 * r + 3] = mean_basis
        rows[r::3, 9:] = c[:, r, :]
    x = np.linalg.lstsq(rows, z.reshape(-1), rcond=None)[0]
    assert np.max(np.abs(solution.bias - x[9:])) / UG < 1e-3
    np.testing.assert_allclose(solution.a, x[:9].reshape(3, 3), rtol=1e-6, atol=1e-6)


def test_static_trial_reports_bias_unobservable():
    cfg = make_config(duration=300, kind="static", errors=PAPER_ERRORS)
    final = run_estimator(cfg, solve_period=100.0).snapshots[-1]
    assert not final.full.observable
    assert final.full.bias is None
    assert final.full.observability.rank == 9
    assert final.gravity_only.observable


def test_swing_makes_all_twelve_states_observable():
    final = run_estimator(make_config(duration=60, errors=PAPER_ERRORS), solve_period=30.0).snapshots[-1]
    assert final.full.observability.rank == 12


def test_paper_scenario_500s_bias_within_10ug_and_three_sigma():
    cfg = make_config(duration=500, rate=100, errors=PAPER_ERRORS, seed=11)
    final = run_estimator(cfg, solve_period=100.0).snapshots[-1]
    error = final.full.bias / UG - np.array([60, 150, 260])
    assert np.all(np.abs(error) < 10)
    assert np.all(np.abs(error) < 3 * final.full.bias_sigma / UG)


def test_method2_level_error_is_a_twentieth_of_method1_without_gyro_errors():
    errors = {k: v for k, v in PAPER_ERRORS.items() if k.startswith("accel")}
    final = run_estimator(make_config(duration=1000, rate=100, errors=errors, seed=3), solve_period=100.0).snapshots[-1]
    level1 = np.abs(final.error_method1[:2])
    level2 = np.abs(final.error_method2[:2])
    assert np.all(level2 <= 0.05 * level1)


def test_the_dual_vector_alignment_recovers_a_known_rotation():
    c = Rotation.from_rotvec([0.3, -1.1, 0.4]).as_matrix()
    earth = Earth.from_degrees(32.0)
    turn = EarthTurn.at(3 * 3600.0, earth)  # the n0 pair: f^n at 0 and f^n0 at t
    v1, v2 = c.T @ earth.f_n, c.T @ turn.f_n0_t
    np.testing.assert_allclose(alignment_matrix(v1, v2, turn), c, atol=1e-14)


def test_theoretical_error_on_a_level_table_is_eq8():
    g = 9.8
    bias = np.array([60, 150, 0]) * UG  # east (x) and north (y) on a level, north-facing body
    pitch, roll = theoretical_error(bias, np.eye(3), g)
    assert pitch == pytest.approx(bias[1] / g, rel=1e-6)  # phi_E = b_N / g
    assert roll == pytest.approx(-bias[0] / g, rel=1e-6)  # phi_N = -b_E / g


def test_attitude_error_is_the_euler_difference():
    ref = euler_matrix(np.array([0.1, 0.02, -0.03]))
    est = euler_matrix(np.array([0.1 + 1e-4, 0.02 - 2e-5, -0.03 + 3e-5]))
    np.testing.assert_allclose(attitude_error(est, ref), [-2e-5, 3e-5, 1e-4], atol=1e-12)


def test_table_referenced_bias_recovers_bias_and_an_unconfigured_tilt():
    tilt = {"tilt_deg": [0.01, -0.02]}
    cfg = make_config(duration=300, errors={"accel_bias_ug": [60, 150, 260]}, turntable=tilt)
    est = run_estimator(cfg, solve_period=100.0, geometry=TableGeometry())  # the estimator does not know the tilt
    result = est.table_referenced()
    # the tilt enters linearised: the neglected g |tilt|^2 / 2 is 0.06 ug at 0.02 deg
    np.testing.assert_allclose(result.bias / UG, [60, 150, 260], atol=0.1)
    np.testing.assert_allclose(result.tilt / DEG, [0.01, -0.02], atol=1e-5)


def test_sample_by_sample_updates_equal_batch_updates():
    from emulators.simulation import Simulation
    from hil.estimation.online import OnlineEstimator
    from hil.samples import AlignedSample

    cfg = make_config(duration=12, rate=100, errors=PAPER_ERRORS)
    sim = Simulation.from_config(cfg)
    live = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=5.0)
    batch_est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=5.0)
    snapshots = []
    for batch in sim.batches(chunk=700):
        batch_est.update_many(batch)
        for k in range(len(batch)):
            sample = AlignedSample(float(batch.t[k]), tuple(batch.dtheta[k]), tuple(batch.dv[k]), tuple(batch.angles[k]))
            snap = live.update(sample)
            if snap is not None:
                snapshots.append(snap.t)
    assert snapshots == [5.0, 10.0]
    a, b = live.solution(), batch_est.solution()
    # 12 s into a trial the gravity parameters are barely determined: equal to summation order only
    np.testing.assert_allclose(a.full.a_internal, b.full.a_internal, rtol=1e-7)
    np.testing.assert_allclose(a.attitude, b.attitude, atol=1e-12)
    np.testing.assert_allclose(a.error_method2, b.error_method2, atol=1e-8)


def test_a_solve_instant_inside_a_data_gap_is_served_by_the_next_sample():
    from emulators.simulation import Simulation
    from hil.estimation.online import OnlineEstimator

    cfg = make_config(duration=30, rate=100, errors=PAPER_ERRORS)
    batches = list(Simulation.from_config(cfg).batches(chunk=1000))  # 0-10 s, 10-20 s, 20-30 s
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=7.0)
    est.update_many(batches[0])
    b = batches[1]  # 15-20 s; the solve at 14 s falls in the gap
    gap = AlignedBatch(b.t[500:], b.dtheta[500:], b.dv[500:], b.angles[500:], float(b.t[499]))
    est.update_many(gap)
    times = [s.t for s in est.snapshots]
    assert times == [7.0, pytest.approx(15.01)]
    assert est.snapshots[-1].samples == 1001


def test_rodrigues_and_cross_kernels_match_scipy_and_numpy():
    from scipy.spatial.transform import Rotation

    from hil.estimation.strapdown import cross, orthonormalised, rotation_matrices

    rng = np.random.default_rng(5)
    for scale in (1e-9, 1e-4, 0.3, 3.0):
        v = rng.normal(size=(50, 3)) * scale
        np.testing.assert_allclose(rotation_matrices(v.T).transpose(2, 0, 1), Rotation.from_rotvec(v).as_matrix(),
                                   atol=2e-16 * 8)
    u, w = rng.normal(size=(2, 20, 3))
    np.testing.assert_allclose(cross(u.T, w.T).T, np.cross(u, w), atol=1e-15)
    c = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix() * (1 + 1e-9)
    np.testing.assert_allclose(orthonormalised(c) @ orthonormalised(c).T, np.eye(3), atol=1e-15)


def test_rodrigues_factors_match_the_trigonometric_forms_on_both_sides_of_the_series_limit():
    from hil.estimation.strapdown import SERIES_LIMIT, rodrigues_factors

    rng = np.random.default_rng(6)
    directions = rng.normal(size=(400, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    angles = np.concatenate((np.geomspace(1e-12, 2.0, 380), np.sqrt(SERIES_LIMIT) * (1 + np.linspace(-1e-6, 1e-6, 20))))
    sin_a, cos_a = rodrigues_factors((directions * angles[:, None]).T)
    np.testing.assert_allclose(sin_a, np.sin(angles) / angles, rtol=4e-16)
    np.testing.assert_allclose(cos_a, 2.0 * np.sin(angles / 2.0) ** 2 / angles**2, rtol=4e-16)  # no cancellation


def test_mean_rotation_is_the_weighted_mean_of_the_rotation_matrices():
    from scipy.spatial.transform import Rotation

    from hil.estimation.strapdown import WEIGHTS, mean_rotation, rodrigues_factors

    rng = np.random.default_rng(7)
    for scale in (1e-6, 0.01, 0.5):
        vectors = rng.normal(size=(40, 3, 3)) * scale
        component_major = vectors.transpose(2, 1, 0)  # (3, K, N)
        sin_a, cos_a = rodrigues_factors(component_major)
        expected = np.einsum("nkij,k->nij", Rotation.from_rotvec(vectors.reshape(-1, 3)).as_matrix().reshape(40, 3, 3, 3),
                             WEIGHTS)
        np.testing.assert_allclose(mean_rotation(component_major, sin_a, cos_a, WEIGHTS).transpose(2, 0, 1), expected,
                                   atol=1e-15)


def test_a_damaged_specific_force_is_left_out():
    import dataclasses

    from emulators.simulation import Simulation
    from hil.estimation.online import OnlineEstimator

    cfg = make_config(duration=60, rate=100, errors=PAPER_ERRORS)
    sim = Simulation.from_config(cfg)
    batch = next(sim.batches(chunk=10**9))
    damaged = batch.dv.copy()
    damaged[3000, 2] *= 1.01  # a flipped mantissa bit the checksum missed: ~10 mg for one sample
    results = []
    for dv in (batch.dv, damaged):
        est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=60.0)
        est.update_many(dataclasses.replace(batch, dv=dv))
        results.append((est.solution().full.bias, est.outliers))
    (clean, clean_outliers), (bias, outliers) = results
    assert clean_outliers == 0 and outliers == 1
    np.testing.assert_allclose(bias, clean, atol=0.05 * 9.80665e-6)  # 0.05 ug: one sample of 6000 fewer


def test_snapshot_history_stays_bounded_and_keeps_the_latest():
    from emulators.simulation import Simulation
    from hil.estimation.online import OnlineEstimator

    cfg = make_config(duration=100, rate=50, errors=PAPER_ERRORS)
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0, max_snapshots=16)
    for batch in sim.batches(chunk=500):
        est.update_many(batch)
    times = [s.t for s in est.snapshots]
    assert len(times) <= 16 and times[-1] == pytest.approx(100.0) and times == sorted(times)
    assert times[0] == pytest.approx(1.0)  # the start of the trial is kept, at a coarser spacing


def test_earth_turn_is_the_earth_rotation_since_the_start():
    """EarthTurn.at against scipy's rotation about the earth axis."""
    earth = Earth.from_degrees(34.2, 400.0)
    turn = EarthTurn.at(5400.0, earth)
    c_n_n0 = earth_turn(earth, 5400.0).as_matrix()[0]
    np.testing.assert_allclose(turn.c_n0_n, c_n_n0.T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(turn.f_n0_t, c_n_n0 @ earth.f_n, rtol=0, atol=1e-14)


def test_table_angles_wrapped_at_180_deg_give_the_same_estimate_as_continuous_ones():
    import dataclasses

    from emulators.simulation import Simulation
    from hil.estimation.online import OnlineEstimator

    cfg = make_config(duration=40, rate=100, errors=PAPER_ERRORS,
                      turntable={"motion": {"kind": "rate", "axes": {"outer": {"rate_dps": 10}}}})
    sim = Simulation.from_config(cfg)
    batches = list(sim.batches(chunk=1000))
    assert np.ptp(np.concatenate([b.angles[:, 0] for b in batches])) > 350 * DEG  # the outer axis passes 180 deg
    results = []
    for wrap in (False, True):
        est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=10.0)
        for b in batches:
            angles = (b.angles + np.pi) % (2 * np.pi) - np.pi if wrap else b.angles  # as a table reports them
            est.update_many(dataclasses.replace(b, angles=angles))
        results.append((est.table_referenced(), est.solution()))
    (table_c, snap_c), (table_w, snap_w) = results
    np.testing.assert_allclose(table_w.bias, table_c.bias, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(snap_w.error_method2, snap_c.error_method2, atol=1e-12)
