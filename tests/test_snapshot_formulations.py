"""A snapshot against the same quantities in a plain formulation: each model's normal equations built
and solved on their own with scipy.linalg (eigh, cho_factor/cho_solve, the full covariance)."""

import numpy as np
import pytest
import scipy.linalg

from emulators.simulation import Simulation
from hil.estimation.apparent_gravity import N_DRIFT, N_FULL, N_GRAVITY
from hil.estimation.online import OnlineEstimator
from tests.conftest import PAPER_ERRORS, make_config

RTOL = 1e-12


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
    out = {"a_internal": x[:N_GRAVITY].reshape(3, 3), "noise_sigma": np.sqrt(noise_var), "eigenvalues": eig,
           "rank": n, "condition": eig[-1] / eig[0]}
    if n == N_GRAVITY:
        return out
    cov = noise_var * np.outer(d, d) * scipy.linalg.cho_solve(factor, np.eye(n))
    out.update(bias=x[N_GRAVITY:N_FULL], bias_sigma=np.sqrt(np.diag(cov)[N_GRAVITY:N_FULL]))
    if n == N_DRIFT:
        for name, dt in (("bias_t0", -tau), ("bias", t - tau)):
            jacobian = np.hstack((np.eye(3), dt * np.eye(3)))  # b(t) = b_c + k (t - tau)
            out[name] = jacobian @ x[N_GRAVITY:]
            out[f"{name}_sigma"] = np.sqrt(np.diag(jacobian @ cov[N_GRAVITY:, N_GRAVITY:] @ jacobian.T))
        out.update(drift=x[N_FULL:], drift_sigma=np.sqrt(np.diag(cov)[N_FULL:]))
    return out


def assert_solution_is(solution, expected: dict) -> None:
    for name, value in expected.items():
        if name == "rank":
            assert solution.observability.rank == value
        elif name in ("eigenvalues", "condition"):
            np.testing.assert_allclose(getattr(solution.observability, name), value, rtol=RTOL, atol=0, err_msg=name)
        else:
            np.testing.assert_allclose(getattr(solution, name), value, rtol=RTOL, atol=0, err_msg=name)


@pytest.mark.parametrize("bias_model", ["constant", "drift"])
def test_snapshot_solutions_equal_each_model_solved_alone(bias_model):
    cfg = make_config(duration=240, rate=50, errors={**PAPER_ERRORS, "accel_drift_ug_per_h": [30, -20, 10]})
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1e9, bias_model=bias_model)
    for batch in sim.batches(chunk=4000):  # a snapshot every 80 s
        est.update_many(batch)
        snap = est.solution()
        gravity = est.gravity
        assert snap.full.observable and snap.full.states == (N_DRIFT if bias_model == "drift" else N_FULL)
        assert_solution_is(snap.full, reference_solve(gravity.normal, gravity.t, snap.full.states))
        assert_solution_is(snap.gravity_only, reference_solve(gravity.normal, gravity.t, N_GRAVITY))
        drift = reference_solve(gravity.normal, gravity.t, N_DRIFT)
        np.testing.assert_allclose(snap.drift_check.drift, drift["drift"], rtol=RTOL, atol=0)
        np.testing.assert_allclose(snap.drift_check.sigma, drift["drift_sigma"], rtol=RTOL, atol=0)
