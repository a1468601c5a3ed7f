"""Bias repeatability and drift (15-state model), the drift check, convergence, and the site's true gravity."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from emulators.simulation import Simulation
from hil.estimation.apparent_gravity import DRIFT_FLOOR, N_DRIFT, ApparentGravityEstimator
from hil.estimation.convergence import BIAS_TOLERANCE, convergence_time
from hil.estimation.online import OnlineEstimator
from hil.frames import EARTH_RATE, Earth, TableGeometry, site_specific_force
from hil.units import ARCSEC, UG
from tests.helpers import PAPER_ERRORS, make_config

UG_PER_H = UG / 3600.0
BIAS = np.array([60.0, 150.0, 260.0]) * UG
DRIFT = np.array([2.0, -1.5, 3.0]) * UG_PER_H
DRIFT_UG_PER_H = [600.0, -400.0, 500.0]


def with_site(cfg, **keys):
    return cfg.model_copy(update={"site": cfg.site.model_copy(update=keys)})


def synthetic(rng, n, drift, noise=50 * UG, dt=1.0):
    """Mean specific force in i_b0 of a swinging body: paper-basis gravity, bias b_s + k t, white noise."""
    t_end = np.arange(1, n + 1) * dt
    t_start = t_end - dt
    mid = 0.5 * (t_start + t_end)
    c = Rotation.from_rotvec(0.2 * np.sin(np.outer(mid, [0.7, 0.9, 0.5]))).as_matrix()
    a_true = np.array([[1e-3, 2e-3, 9.0], [-3e-3, 1e-3, 3.0], [2e-3, 4e-3, 2.0]])
    basis = np.column_stack((np.cos(EARTH_RATE * mid), np.sin(EARTH_RATE * mid), np.ones(n)))
    z = basis @ a_true.T + c @ BIAS + (c @ drift) * mid[:, None] + rng.normal(scale=noise, size=(n, 3))
    return t_start, t_end, c, z


def feed(est, t_start, t_end, c, z, chunk=700):
    for k in range(0, len(z), chunk):  # uneven chunks
        est.update_many(t_start[k : k + chunk], t_end[k : k + chunk], z[k : k + chunk], c[k : k + chunk])


def run(cfg, bias_model="constant", solve_period=100.0, batches=None):
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=solve_period, bias_model=bias_model)
    for batch in batches if batches is not None else sim.batches():
        est.update_many(batch)
    est.finish()
    return est


def test_fifteen_state_information_form_equals_batch_least_squares():
    """The stacked 2018 eq. 90 / 2019 eq. 14 system with columns [mean basis, C, C t] solved by lstsq."""
    n = 3000
    t_start, t_end, c, z = synthetic(np.random.default_rng(5), n, DRIFT * 3600)
    est = ApparentGravityEstimator()
    feed(est, t_start, t_end, c, z)
    solution = est.solve(N_DRIFT)
    mid = 0.5 * (t_start + t_end)
    sinc = np.sin(0.5 * EARTH_RATE) / (0.5 * EARTH_RATE)
    mean_basis = np.column_stack((np.cos(EARTH_RATE * mid) * sinc, np.sin(EARTH_RATE * mid) * sinc, np.ones(n)))
    rows = np.zeros((3 * n, 15))
    for r in range(3):
        rows[r::3, 3 * r : 3 * r + 3] = mean_basis
        rows[r::3, 9:12] = c[:, r, :]
        rows[r::3, 12:] = c[:, r, :] * mid[:, None]
    x, rss = np.linalg.lstsq(rows, z.reshape(-1), rcond=None)[:2]
    cov = rss[0] / (3 * n - 15) * np.linalg.inv(rows.T @ rows)
    assert solution.observability.rank == 15
    np.testing.assert_allclose(solution.bias_t0 / UG, x[9:12] / UG, atol=1e-3)
    np.testing.assert_allclose(solution.drift / UG_PER_H, x[12:] / UG_PER_H, atol=1e-3)
    np.testing.assert_allclose(solution.bias / UG, (x[9:12] + x[12:] * t_end[-1]) / UG, atol=1e-3)
    np.testing.assert_allclose(solution.a, x[:9].reshape(3, 3), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(solution.drift_sigma, np.sqrt(np.diag(cov)[12:]), rtol=1e-6)
    np.testing.assert_allclose(solution.bias_t0_sigma, np.sqrt(np.diag(cov)[9:12]), rtol=1e-6)
    end = np.hstack((np.eye(3), t_end[-1] * np.eye(3)))  # d(b_s + k t) / d(b_s, k)
    np.testing.assert_allclose(solution.bias_sigma, np.sqrt(np.diag(end @ cov[9:, 9:] @ end.T)), rtol=1e-6)


def test_drift_sigma_is_the_error_made_over_many_seeds():
    errors, sigmas = [], []
    for seed in range(150):
        est = ApparentGravityEstimator()
        feed(est, *synthetic(np.random.default_rng(seed), 2000, DRIFT * 3600), chunk=2000)
        s = est.solve(N_DRIFT)
        errors.append(np.concatenate((s.drift - DRIFT * 3600, s.bias_t0 - BIAS)))
        sigmas.append(np.concatenate((s.drift_sigma, s.bias_t0_sigma)))
    ratio = np.std(errors, axis=0) / np.mean(sigmas, axis=0)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio
    assert np.all(np.abs(np.mean(errors, axis=0)) < 0.3 * np.mean(sigmas, axis=0))  # unbiased


def test_error_free_drifting_swing_recovers_repeatability_and_drift():
    errors = {"accel_bias_ug": [60, 150, 260], "accel_drift_ug_per_h": [2, -1.5, 3]}
    final = run(make_config(duration=600, rate=100, errors=errors), "drift").solution().full
    assert final.states == N_DRIFT and final.observable
    np.testing.assert_allclose(final.bias_t0 / UG, BIAS / UG, atol=0.01)
    np.testing.assert_allclose(final.drift / UG_PER_H, DRIFT / UG_PER_H, atol=0.001)
    np.testing.assert_allclose(final.bias / UG, (BIAS + DRIFT * 600) / UG, atol=0.01)  # the bias at the end


@pytest.fixture(scope="module")
def drifting_trial():
    """800 s of the paper's swing at 50 Hz, 50 ug noise, drift [600, -400, 500] ug/h (5-10 sigma)."""
    errors = {**PAPER_ERRORS, "accel_drift_ug_per_h": DRIFT_UG_PER_H}
    cfg = make_config(duration=800, rate=50, errors=errors, seed=5)
    return cfg, list(Simulation.from_config(cfg).batches())


def test_emulated_drift_is_recovered_within_three_sigma(drifting_trial):
    cfg, batches = drifting_trial
    est = run(cfg, "drift", batches=batches)
    final = est.solution()
    truth = np.array(DRIFT_UG_PER_H) * UG_PER_H
    assert np.all(np.abs(final.full.drift - truth) < 3 * final.full.drift_sigma)
    assert np.all(np.abs(final.full.bias_t0 - BIAS) < 3 * final.full.bias_t0_sigma)
    assert np.all(np.abs(final.full.bias - (BIAS + truth * 800)) < 3 * final.full.bias_sigma)
    np.testing.assert_array_equal(final.drift_check.drift, final.full.drift)  # the same 15-state sums
    assert final.error_theoretical is not None


def test_constant_model_flags_an_unmodelled_drift(drifting_trial):
    cfg, batches = drifting_trial
    final = run(cfg, "constant", batches=batches).solution()
    assert final.full.states == 12 and final.full.drift is None
    assert final.drift_check.significant
    assert np.max(np.abs(final.drift_check.drift / final.drift_check.sigma)) > 4


def test_drift_check_is_quiet_without_drift():
    final = run(make_config(duration=800, rate=50, errors=PAPER_ERRORS, seed=5), "constant").solution()
    assert not final.drift_check.significant


def test_a_noise_free_trial_is_not_called_drifting_on_the_arithmetic_floor():
    """Without noise the drift's sigma is the arithmetic's (~1e-9 ug/h): the drift it finds is of the same
    order and must not be called significant."""
    final = run(make_config(duration=300, rate=50, errors={"accel_bias_ug": [60, 150, 260]}), "constant").solution()
    assert np.all(final.drift_check.sigma < DRIFT_FLOOR) and not final.drift_check.significant
    drifting = {"accel_bias_ug": [60, 150, 260], "accel_drift_ug_per_h": [0, 0, 0.5]}
    assert run(make_config(duration=300, rate=50, errors=drifting), "constant").solution().drift_check.significant


def test_static_trial_reports_drift_unobservable():
    final = run(make_config(duration=100, kind="static", errors=PAPER_ERRORS), "drift").solution()
    assert final.full.bias is None and final.full.drift is None and final.drift_check is None


def test_unknown_bias_model_is_refused():
    with pytest.raises(ValueError, match="bias_model 'linear'"):
        OnlineEstimator(Earth.from_degrees(32.0), bias_model="linear")


def solve_track(t_start, t_end, c, z, period):
    """Times, biases and sigmas of the 12-state solution every ``period`` samples."""
    est = ApparentGravityEstimator()
    stops = list(range(period, len(z) + 1, period))
    rows = [(est.t, s.bias, s.bias_sigma) for _ in est.update_segments(t_start, t_end, z, c, stops)
            if (s := est.solve()).bias is not None]
    return tuple(np.array(col) for col in zip(*rows, strict=True))


def test_convergence_time_is_the_same_for_a_ten_minute_and_a_24_hour_trial():
    """The 24-hour trial's data begins with the 10-minute trial's: both converge at the same instant,
    where the final 3-sigma band (0.1 ug after 24 h) would put the long one hours later."""
    data = synthetic(np.random.default_rng(3), 86400, np.zeros(3), noise=5 * UG)
    long = solve_track(*data, period=30)
    short = solve_track(*(x[:600] for x in data), period=30)
    times = [convergence_time(*track, BIAS_TOLERANCE) for track in (short, long)]
    assert times[0] is not None and times[0] < 600
    assert times[1] == times[0]
    t, bias, sigma = long
    outside_final_band = np.flatnonzero(np.any(np.abs(bias - bias[-1]) > 3 * sigma[-1], axis=1))
    assert t[outside_final_band[-1] + 1] > 3600


def test_estimator_convergence_uses_every_solve_not_the_thinned_history():
    cfg = make_config(duration=400, rate=50, errors={**PAPER_ERRORS, "accel_noise_ug": [20, 20, 20]}, seed=4)
    sim = Simulation.from_config(cfg)
    full, thinned = (OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=10.0, max_snapshots=m)
                     for m in (1000, 8))
    for batch in sim.batches():
        full.update_many(batch)
        thinned.update_many(batch)
    snaps = full.snapshots
    assert len(snaps) == 40  # every solve kept: the definition applied to them here, independently
    t = np.array([s.t for s in snaps])
    bias, sigma = (np.array([np.full(3, np.nan) if v is None else v for v in values])
                   for values in ([s.full.bias for s in snaps], [s.full.bias_sigma for s in snaps]))

    def settled(j: int) -> bool:  # known to the tolerance, and every later estimate within it
        return bool(np.all(3 * sigma[j] <= BIAS_TOLERANCE) and np.all(np.abs(bias[j:] - bias[j]) <= BIAS_TOLERANCE))

    expected = next((t[k] for k in range(len(t)) if all(settled(j) for j in range(k, len(t)))), None)
    assert expected is not None and full.bias_converged_at() == expected
    assert thinned.bias_converged_at() == full.bias_converged_at()
    assert len(thinned.snapshots) <= 8


def test_site_gravity_is_normal_gravity_turned_by_the_deflection():
    earth = Earth.from_degrees(32.0)
    np.testing.assert_array_equal(site_specific_force(earth), earth.f_n)
    xi, eta = 20 * ARCSEC, -15 * ARCSEC
    f = site_specific_force(earth, (xi, eta), 50e-5)
    assert np.linalg.norm(f) == pytest.approx(earth.g + 50e-5, rel=1e-15)
    np.testing.assert_allclose(f[:2] / f[2], [np.tan(eta), np.tan(xi)], rtol=1e-12)  # zenith north and east


def test_deflection_leaves_the_self_calibrated_bias_and_becomes_table_tilt():
    """Self-calibration estimates the gravity direction, so the bias is unchanged; the table reference
    (normal gravity) takes the deflection as a base tilt: ``(I - [delta x]) [0, 0, g] = g [eta, xi, 1]``
    gives ``delta = (xi, -eta)`` about east and north."""
    deflection = (20.0, -15.0)
    cfg = make_config(duration=300, rate=50, errors=PAPER_ERRORS, seed=2)
    plain = run(cfg).solution().full
    moved = run(with_site(cfg, deflection_arcsec=deflection, gravity_anomaly_mgal=30.0)).solution().full
    np.testing.assert_allclose(moved.bias / UG, plain.bias / UG, atol=0.01)
    assert np.all(np.abs(moved.bias - BIAS) < 4 * moved.bias_sigma)

    cfg = with_site(make_config(duration=300, rate=50, errors={"accel_bias_ug": [60, 150, 260]}),
                    deflection_arcsec=deflection)
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, TableGeometry(), solve_period=100.0)
    for batch in sim.batches():
        est.update_many(batch)
    table = est.table_referenced()
    np.testing.assert_allclose(table.tilt / ARCSEC, [20.0, 15.0], atol=0.05)
    np.testing.assert_allclose(table.bias / UG, BIAS / UG, atol=0.1)


def test_the_table_referenced_drift_has_the_error_its_sigma_says_over_seeds():
    """f_b = C_n^b f^n + b_s + k t + noise with known attitudes (2018 eq. 90 in the table-referenced model): the
    drift rate fitted beside the constant bias is k, and its error over 200 seeds is its sigma."""
    from hil.estimation.table_reference import TableReferenceEstimator

    f_n = np.array([0.0, 0.0, 9.79])
    n, dt = 600, 0.5
    t_mid = (np.arange(n) + 0.5) * dt
    c_bn = Rotation.from_rotvec(0.3 * np.sin(np.outer(t_mid, [0.7, 0.9, 0.5]))).as_matrix()  # (N, 3, 3) C_b^n
    ideal = c_bn.transpose(0, 2, 1) @ f_n + BIAS + np.outer(t_mid, DRIFT * 3600.0)  # 7200, -5400, 10800 ug/h
    errors = []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        est = TableReferenceEstimator(f_n)
        for _ in est.update_segments(t_mid, ideal + rng.normal(scale=50 * UG, size=(n, 3)),
                                     c_bn.transpose(1, 2, 0).copy(), [n]):
            pass
        solved = est.solve()
        errors.append((solved.drift - DRIFT * 3600.0) / solved.drift_sigma)
    errors = np.array(errors)
    assert np.abs(errors.mean(axis=0)).max() < 0.25
    assert 0.85 < errors.std() < 1.15


def test_drift_rates_agree_within_four_combined_sigmas_on_every_axis():
    from hil.estimation.table_reference import drifts_agree

    assert drifts_agree([10.0, 0.0, 0.0], [2.0, 1.0, 1.0], [2.5, 0.0, 0.0], [1.0, 1.0, 1.0])  # 7.5 < 4 * 2.24
    assert not drifts_agree([10.0, 0.0, 0.0], [1.5, 1.0, 1.0], [0.0, 0.0, 0.0], [0.5, 1.0, 1.0])  # 10 > 4 * 1.58
