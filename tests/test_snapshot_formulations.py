"""A snapshot against the same quantities in a plain formulation: each model's normal equations built
and solved on their own with scipy.linalg (eigh, cho_factor/cho_solve, the full covariance), and the
alignment as the 2014 paper writes it (eq. 8 by a linear solve, eq. 9 by scipy's polar decomposition,
the earth turn, the tilt and the Euler angles by scipy rotations).

The estimator solves by LU (numpy), the reference by Cholesky, so they agree to the solves' rounding:
in the scaled states y, ``|dy| <= cond eps max|y|`` (the normwise forward error of a backward stable
solve); the noise level, and with it every sigma, comes from the residual sum of squares
``z'z - 2 y'r + y'Sy``, whose cancellation magnifies rounding by ``z'z / rss`` (about 1e8 here)."""

import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.transform import Rotation

from emulators.simulation import Simulation
from hil.estimation.apparent_gravity import N_DRIFT, N_FULL, N_GRAVITY
from hil.estimation.online import OnlineEstimator
from hil.frames import EULER_SEQ
from tests.helpers import PAPER_ERRORS, earth_turn, make_config, scipy_attitude

EPS = np.finfo(float).eps
ANGLE_ATOL = 1e-13  # rad; the errors are Euler differences, each angle rounded to ~1e-16 rad


def reference_solve(normal, t: float, n: int) -> dict:
    """Model n alone: the 15-state one re-centred at t/2 by ``T^T W T``; scaled to unit diagonal, solved
    by Cholesky, the covariance ``s^2 D W_scaled^-1 D`` in full and the bias at 0 and t as ``J P J^T``."""
    info, rhs = normal.info.copy(), normal.rhs.copy()
    tau = 0.5 * t
    if n == N_DRIFT:
        change = np.eye(N_DRIFT)
        change[N_GRAVITY:N_FULL, N_FULL:] = -tau * np.eye(3)
        info, rhs = change.T @ info @ change, change.T @ rhs
    info, rhs = info[:n, :n], rhs[:n]
    d = 1.0 / np.sqrt(np.diag(info))
    scaled, rhs_scaled = info * np.outer(d, d), rhs * d
    eig = scipy.linalg.eigh(scaled, eigvals_only=True)
    factor = scipy.linalg.cho_factor(scaled)
    y = scipy.linalg.cho_solve(factor, rhs_scaled)
    x = d * y
    rss = normal.zz - 2.0 * y @ rhs_scaled + y @ scaled @ y
    noise_var = rss / (3 * normal.samples - n)
    x_atol = EPS * (eig[-1] / eig[0]) * np.abs(y).max() * d  # per state, from the scaled solve's bound
    tolerance = {"a_internal": x_atol[:N_GRAVITY].reshape(3, 3), "bias": x_atol[N_GRAVITY:N_FULL],
                 "drift": x_atol[N_FULL:], "sigma_rtol": 8.0 * EPS * normal.zz / rss}
    out = {"a_internal": x[:N_GRAVITY].reshape(3, 3), "noise_sigma": np.sqrt(noise_var), "eigenvalues": eig,
           "rank": n, "condition": eig[-1] / eig[0], "tolerance": tolerance}
    if n == N_GRAVITY:
        return out
    cov = noise_var * np.outer(d, d) * scipy.linalg.cho_solve(factor, np.eye(n))
    out.update(bias=x[N_GRAVITY:N_FULL], bias_sigma=np.sqrt(np.diag(cov)[N_GRAVITY:N_FULL]))
    if n == N_DRIFT:
        for name, dt in (("bias_t0", -tau), ("bias", t - tau)):
            jacobian = np.hstack((np.eye(3), dt * np.eye(3)))  # b(t) = b_c + k (t - tau)
            out[name] = jacobian @ x[N_GRAVITY:]
            tolerance[name] = x_atol[N_GRAVITY:N_FULL] + abs(dt) * x_atol[N_FULL:]
            out[f"{name}_sigma"] = np.sqrt(np.diag(jacobian @ cov[N_GRAVITY:, N_GRAVITY:] @ jacobian.T))
        out.update(drift=x[N_FULL:], drift_sigma=np.sqrt(np.diag(cov)[N_FULL:]))
    return out


def assert_within(actual: np.ndarray, expected: np.ndarray, atol: np.ndarray, name: str) -> None:
    """Element-wise ``|actual - expected| <= atol`` with a per-element atol."""
    error = np.abs(np.asarray(actual) - expected)
    assert np.all(error <= atol), f"{name}: error {error} beyond {atol}"


def assert_solution_is(solution, expected: dict) -> None:
    tolerance = expected["tolerance"]
    for name, value in expected.items():
        if name == "rank":
            assert solution.observability.rank == value
        elif name == "eigenvalues":  # perfectly conditioned: |d lambda| <= |dS| ~ n eps |S|
            np.testing.assert_allclose(solution.observability.eigenvalues, value, rtol=0, atol=1e-14 * value[-1])
        elif name == "condition":
            np.testing.assert_allclose(solution.observability.condition, value, rtol=1e-14 * value, atol=0)
        elif name in tolerance:
            assert_within(getattr(solution, name), value, tolerance[name], name)
        elif name != "tolerance":  # the noise level and the sigmas
            np.testing.assert_allclose(getattr(solution, name), value, rtol=tolerance["sigma_rtol"], atol=0,
                                       err_msg=name)


def reference_errors(snap, earth, c_b_n: np.ndarray) -> list[np.ndarray]:
    """Method 1, method 2 and the theoretical error (2019 eq. 8) of a snapshot against the table attitude."""

    def triad(v1, v2):
        c = np.cross(v1, v2)
        return np.vstack((v1, c, np.cross(c, v1)))

    def error(estimate):
        diff = Rotation.from_matrix(estimate).as_euler(EULER_SEQ) - Rotation.from_matrix(c_b_n).as_euler(EULER_SEQ)
        return ((diff + np.pi) % (2 * np.pi) - np.pi)[[1, 2, 0]]  # (pitch, roll, yaw)

    c_n_n0 = earth_turn(earth, snap.t).as_matrix()[0]
    out = []
    for solution in (snap.gravity_only, snap.full):
        g0, gt = solution.apparent_gravity(np.array([0.0, snap.t]))
        eq8 = np.linalg.solve(triad(g0, gt), triad(earth.f_n, c_n_n0 @ earth.f_n)).T
        out.append(error(c_n_n0.T @ scipy.linalg.polar(eq8)[0] @ snap.attitude))
    b_n = c_b_n @ snap.full.bias
    tilt = Rotation.from_rotvec([b_n[1] / earth.g, -b_n[0] / earth.g, 0.0]).as_matrix()
    return [*out, error(tilt @ c_b_n)[:2]]


def snapshots(bias_model: str):
    """(snapshot, estimator, table attitude C_b^n) every 80 s of a 240 s swing with the paper's errors and a drift."""
    cfg = make_config(duration=240, rate=50, errors={**PAPER_ERRORS, "accel_drift_ug_per_h": [30, -20, 10]})
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1e9, bias_model=bias_model)
    for batch in sim.batches(chunk=4000):
        est.update_many(batch)
        yield est.solution(), est, scipy_attitude(sim.truth.geometry, batch.angles[-1]).as_matrix()


@pytest.mark.parametrize("bias_model", ["constant", "drift"])
def test_snapshot_solutions_equal_each_model_solved_alone(bias_model):
    for snap, est, _ in snapshots(bias_model):
        gravity = est.gravity
        assert snap.full.observable and snap.full.states == (N_DRIFT if bias_model == "drift" else N_FULL)
        assert_solution_is(snap.full, reference_solve(gravity.normal, gravity.t, snap.full.states))
        assert_solution_is(snap.gravity_only, reference_solve(gravity.normal, gravity.t, N_GRAVITY))
        drift = reference_solve(gravity.normal, gravity.t, N_DRIFT)
        assert_within(snap.drift_check.drift, drift["drift"], drift["tolerance"]["drift"], "drift check")
        np.testing.assert_allclose(snap.drift_check.sigma, drift["drift_sigma"], rtol=drift["tolerance"]["sigma_rtol"],
                                   atol=0)


@pytest.mark.parametrize("bias_model", ["constant", "drift"])
def test_snapshot_alignment_errors_equal_the_papers_construction(bias_model):
    for snap, est, c_b_n in snapshots(bias_model):
        expected = reference_errors(snap, est.earth, c_b_n)
        for name, value in zip(("error_method1", "error_method2", "error_theoretical"), expected):
            np.testing.assert_allclose(getattr(snap, name), value, rtol=0, atol=ANGLE_ATOL, err_msg=name)
