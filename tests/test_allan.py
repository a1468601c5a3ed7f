"""Allan deviation, its EDF and intervals, and the fitted noise terms, against analytic cases."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from emulators.sensor_errors import BiasInstability, SensorErrorModel
from hil.config import ImuErrors
from hil.estimation import allan
from hil.arguments import build_parser
from hil.estimation.allan_cov import MODEL_ALPHAS, avar_covariance, noise_products
from hil.estimation.allan_detrend import DETRENDS, linear_trend
from hil.estimation.allan_edf import basic_sum, greenhall_edf, sz
from hil.estimation.allan_fit import FLICKER_FLOOR, Term
from hil.estimation.allan_noise_id import identify
from hil.estimation.allan_taus import octave_factors
from hil.outputs.noise import noise_document, write_noise
from hil.outputs.noise_section import noise_section
from hil.units import DEG, DEG_PER_H, UG

T = 0.01  # s, 100 Hz


def _exact_edf(cov: np.ndarray, m: int) -> float:
    """EDF of the overlapping Allan variance for rates of covariance cov (n, n), exact for Gaussian rates.

    The estimator is y^T Q y with Q = D^T D / (2 M tau^2), D the second differences of the phase in
    terms of the rates; mean tr(Q S), variance 2 tr((Q S)^2), so nu = 2 mean^2 / var = tr(C)^2 / |C|_F^2
    with C = D S D^T.
    """

    def second_difference(a: np.ndarray) -> np.ndarray:  # D a along axis 0, through the prefix sums
        p = np.vstack([np.zeros((1, a.shape[1])), np.cumsum(a, axis=0)])
        return p[2 * m :] - 2.0 * p[m:-m] + p[: -2 * m]

    c = second_difference(second_difference(cov).T)
    return np.trace(c) ** 2 / np.sum(c * c)


def _second_differences(m: int, n: int) -> np.ndarray:
    """D (n + 1 - 2m, n): the second differences x_{k+2m} - 2 x_{k+m} + x_k of the phase, in the n rates."""
    d = np.zeros((n + 1 - 2 * m, n))
    for k in range(n + 1 - 2 * m):
        d[k, k + m : k + 2 * m] += 1.0
        d[k, k : k + m] -= 1.0
    return d


def _gauss_markov_avar(tau: np.ndarray, tc: float, variance: float) -> np.ndarray:
    """Allan variance of a first-order Gauss-Markov process (IEEE 952 Annex C, exponentially correlated)."""
    x = tau / tc
    return 2.0 * variance * tc / tau * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))


def _white(n: int, coefficient: float, columns: int, seed: int) -> np.ndarray:
    """Angle increments of white rate noise with ARW coefficient N: per-sample rate sigma N / sqrt(T)."""
    return np.random.default_rng(seed).standard_normal((n, columns)) * coefficient * math.sqrt(T)


def _emulated(n: int, seed: int, **errors) -> tuple[np.ndarray, np.ndarray]:
    zeros = np.zeros((n, 3))
    return SensorErrorModel(ImuErrors(**errors), 1.0 / T, seed).apply(np.arange(1, n + 1) * T, zeros, zeros)


N = 1024  # rate samples of the exact-EDF cases
INDEX = np.arange(N)
WHITE_COV = np.eye(N)
WALK_COV = np.minimum.outer(INDEX, INDEX) + 1.0  # a rate random walk constant over each interval
# Flicker from the emulator's Gauss-Markov sum at 20 Hz, flat from m = 2 (0.1 s)
FLICKER_COV = sum(np.exp(-0.05 / tc) ** np.abs(np.subtract.outer(INDEX, INDEX))
                  for tc in BiasInstability.CORRELATION_TIMES)
OCTAVES = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512)


@pytest.mark.parametrize(
    "alpha,cov,factors,tol",
    [
        # J <= 100 with F = infinity, Table 2 (r > 3), and r <= 3; below m = 34 the sum takes F = m as Stable32
        # does, which is not the exact EDF of sampled white rate (+17 % at m = 1, -12 % at m = 4)
        (0, WHITE_COV, (34, 64, 100, 128, 256, 300, 512), 2e-3),
        (-2, WALK_COV, (8, 16, 32, 64, 128, 256, 512), 0.015),  # below m = 8 the interval's steps show; F = m: 1.2 %
        (-1, FLICKER_COV, (16, 32, 64, 128, 256, 512), 0.03),
    ],
)
def test_greenhall_edf_matches_the_exact_edf_of_the_quadratic_form(alpha, cov, factors, tol):
    for m in factors:
        assert greenhall_edf(alpha, m, N + 1) == pytest.approx(_exact_edf(cov, m), rel=tol)


@pytest.mark.parametrize("alpha", (0, -1, -2))
def test_greenhall_table_2_is_the_limit_of_the_basic_sum(alpha):
    """Past J = 100 the EDF comes from Table 2's (a0, a1): the same as the sum taken to its end."""
    m, n_phase = 60, 60 * 40 + 120 + 1  # r = 40, J = 180 > 100
    direct = n_phase - 2 * m
    inverse = basic_sum(3 * m, direct, m, math.inf, alpha) / (float(sz(0.0, math.inf, alpha)) ** 2 * direct)
    assert greenhall_edf(alpha, m, n_phase) == pytest.approx(1.0 / inverse, rel=0.01)


def test_white_pm_edf_is_the_exact_edf_of_white_phase_samples():
    """Rates that are differences of white phase (quantisation): the closed form at every r, both sides of 2."""
    cov = 2.0 * np.eye(N) - np.eye(N, k=1) - np.eye(N, k=-1)
    for m in (1, 4, 32, 300, 400, 512):
        assert greenhall_edf(2, m, N + 1) == pytest.approx(_exact_edf(cov, m), rel=1e-9)


def test_flicker_pm_tables_3_and_2_are_the_limits_of_the_basic_sum():
    """alpha = 1 past J = 100: sz(0) is b0 + b1 ln m (Table 3) and the sum's limit Table 2's (790, 410)."""
    for m in (100, 1000, 10_000):
        assert float(sz(0.0, m, 1)) == pytest.approx(15.23 + 12.0 * math.log(m), rel=5e-5)
    m, n_phase = 60, 60 * 40 + 120 + 1
    direct = n_phase - 2 * m
    inverse = basic_sum(3 * m, direct, m, m, 1) / (float(sz(0.0, m, 1)) ** 2 * direct)
    assert greenhall_edf(1, m, n_phase) == pytest.approx(1.0 / inverse, rel=0.015)


def test_the_noise_types_are_identified_from_the_rates_averaged_to_each_tau():
    """Lag-1 where 30 averages or more remain (m <= 1092 of 2^15); below (m = 2048, 16 averages) the B1 ratio
    and R(n), which tell white PM (a quantised angle) from white rate; there the expected B1 for the record's
    samples (as Stable32 takes it) calls a walk of 16 averages flicker."""
    rng = np.random.default_rng(7)
    n = 1 << 15
    white_pm, white = np.diff(rng.standard_normal(n + 1)), rng.standard_normal(n)
    walk = np.cumsum(rng.standard_normal(n))
    flicker, _ = _emulated(n, 8, gyro_bias_instability_dph=[1.0] * 3)
    rates = np.column_stack([white_pm, white, walk])
    np.testing.assert_array_equal(identify(rates, np.array([1, 16, 256, 2048])), [[2, 0, -2]] * 3 + [[2, 0, -1]])
    np.testing.assert_array_equal(identify(flicker[:, 0], np.array([1, 4, 64])), [[-1]] * 3)


def test_the_covariance_of_estimates_at_two_tau_is_the_quadratic_forms():
    """cov(a_i, a_j) = 2 tr(Q_i S Q_j S) for Gaussian rates of covariance S, plus 4 mu^T Q_i S Q_j mu for rates of
    mean mu (a ramp): white PM (quantisation) and white rate exactly (to the sums' integration), the random walk
    constant over each interval from m = 8 (``allan_cov`` takes it continuous), white rate under a ramp."""
    n = 256
    factors = np.array([1, 2, 4, 8, 16, 32, 64])
    counts = n + 1 - 2 * factors
    products = noise_products(factors, counts)
    operators = [_second_differences(int(m), n) for m in factors]
    index = np.arange(n)
    white_pm = 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)  # rates: differences of white phase samples
    ramp = 1e-3 * index  # rates growing by 1e-3 per sample
    cases = ((0, white_pm, 0, 0.0), (1, np.eye(n), 0, 0.0), (3, np.minimum.outer(index, index) + 1.0, 3, 0.0),
             (1, np.eye(n), 0, 1.0))
    for q, cov, first, ramped in cases:
        mu = ramped * ramp
        shared = [[x @ b.T for b in operators] for x in (a @ cov for a in operators)]  # the differences' covariances
        exact = np.array([[(2.0 * np.sum(c * c) + 4.0 * (a @ mu) @ c @ (b @ mu)) / (len(a) * len(b))
                           for b, c in zip(operators, row)] for a, row in zip(operators, shared)])
        parts = np.zeros((len(factors), len(MODEL_ALPHAS) + 1))
        parts[:, q] = [np.trace(a @ cov @ a.T) / len(a) for a in operators]
        parts[:, -1] = [np.mean((a @ mu) ** 2) for a in operators]
        ours = avar_covariance(products, parts)
        np.testing.assert_allclose(ours[first:, first:], exact[first:, first:], rtol=0.01 if q == 3 else 1e-3)


def test_white_noise_gives_arw_over_root_tau_within_the_interval_at_every_tau():
    arw = 0.05 * DEG / 60.0  # 0.05 deg/sqrt(h) in rad/sqrt(s)
    result = allan.analyse(_white(1 << 16, arw, 3, seed=11), T, level=0.999)
    truth = arw / np.sqrt(result.tau)[:, None]
    assert np.all((result.lower <= truth) & (truth <= result.upper))
    for term in result.white:
        assert term.lower <= arw <= term.upper
        assert term.value == pytest.approx(arw, rel=0.02)  # the quantisation term takes a share of the short tau
    assert all(t.value is None for t in result.bias_instability + result.random_walk + result.ramp)
    assert all(t.reason is not None for t in result.bias_instability + result.random_walk + result.ramp)


def test_random_walk_gives_the_half_slope_with_the_configured_coefficient():
    """Rate random walk sampled per interval: avar = K^2 tau / 3 (1 + 1 / (2 m^2)) exactly (sum of the
    squared weights m (2 m^2 + 1) / 3 of the driving steps in one second difference)."""
    k_dph_per_sqrt_h = 2.0
    dtheta, _ = _emulated(1 << 16, 5, gyro_random_walk_dph_per_sqrt_h=[k_dph_per_sqrt_h] * 3)
    result = allan.analyse(dtheta, T, level=0.999)
    k = k_dph_per_sqrt_h * DEG_PER_H / 60.0  # rad/s/sqrt(s)
    m = result.tau / T
    truth = np.sqrt(k**2 * result.tau / 3.0 * (1.0 + 1.0 / (2.0 * m**2)))[:, None]
    assert np.all((result.lower <= truth) & (truth <= result.upper))
    for term in result.random_walk:
        assert term.lower <= k <= term.upper
        assert term.value == pytest.approx(k, rel=0.02)
    assert all(t.value is None and t.upper is not None for t in result.ramp)  # a walk is not a ramp


def test_emulated_bias_instability_is_flat_within_2_percent_from_011_s_to_76000_s():
    tau = np.logspace(math.log10(0.11), math.log10(7.6e4), 200)
    avar = sum(_gauss_markov_avar(tau, tc, math.log(4.0) / math.pi) for tc in BiasInstability.CORRELATION_TIMES)
    assert np.all(np.abs(np.sqrt(avar / FLICKER_FLOOR) - 1.0) < 0.02)


def test_emulated_bias_instability_is_flat_and_read_back_over_white_noise():
    """Configured B and a white noise that dominates below about 1 s; the deviation follows
    sqrt(N^2 / tau + 0.664^2 B^2) within its interval at every tau from 0.11 s to 20 s (1000 averages and
    more: past them Stable32's identification, which the intervals follow, may call flicker white or PM)."""
    b_dph, b_ug, sigma_dph, sigma_ug = 0.5, 20.0, 2.0, 60.0
    dtheta, dv = _emulated(
        1 << 18, 3,
        gyro_bias_instability_dph=[b_dph] * 3, accel_bias_instability_ug=[b_ug] * 3,
        gyro_noise_dph=[sigma_dph] * 3, accel_noise_ug=[sigma_ug] * 3,
    )
    for increments, b, sigma in ((dtheta, b_dph * DEG_PER_H, sigma_dph * DEG_PER_H), (dv, b_ug * UG, sigma_ug * UG)):
        result = allan.analyse(increments, T, level=0.999)
        for term in result.bias_instability:
            assert term.lower <= b <= term.upper
            assert term.value == pytest.approx(b, rel=0.1)
        flat = (result.tau >= 0.11) & (result.tau <= 20.48)
        truth = np.sqrt(sigma**2 * T / result.tau + FLICKER_FLOOR * b**2)[flat, None]
        assert np.all((result.lower[flat] <= truth) & (truth <= result.upper[flat]))


def test_interval_coverage_matches_its_level_over_many_seeds():
    """The chi-square interval of each tau with Greenhall's EDF holds the true deviation as often as its
    level says (the direct sum, Table 2 and the r <= 3 branch)."""
    seeds, n, level = 600, 4096, 0.683
    sigma = 3  # binomial standard deviations allowed
    white = _white(n, 1.0, seeds, seed=1)
    walk = np.cumsum(np.random.default_rng(2).standard_normal((n, seeds)), axis=0) * math.sqrt(T) * T
    # Random walk: from m = 8 (below, the interval's constant rate steps show), to r = 6 (at r = 2, with 2
    # EDF, the estimate's distribution is no longer chi-square: 75 % coverage).
    for increments, alpha, factors in ((white, 0, np.array([1, 8, 64, 512, 1024])), (walk, -2, np.array([8, 64, 512]))):
        truth = 1.0 / (factors * T) if alpha == 0 else factors * T / 3.0 * (1.0 + 1.0 / (2.0 * factors**2))
        avar, counts = allan.overlapping_avar(increments, T, factors)
        nu = np.array([greenhall_edf(alpha, int(m), n + 1) for m in factors])
        lower, upper = allan.chi2_interval(avar, nu[:, None], level)
        hit = np.mean((lower <= truth[:, None]) & (truth[:, None] <= upper), axis=1)
        assert np.all(np.abs(hit - level) < sigma * math.sqrt(level * (1 - level) / seeds)), (alpha, hit)


def test_fitted_term_intervals_hold_the_truth_as_often_as_their_level():
    """White noise and random walk crossing at 5.8 s of a 164 s record: over 200 seeds each term's interval
    holds the truth within 3 binomial standard deviations of its level (neither narrower nor wider)."""
    seeds, level, arw, walk = 200, 0.683, 1.0, 0.3
    rng = np.random.default_rng(4)
    increments = (rng.standard_normal((1 << 14, seeds)) * arw * math.sqrt(T)
                  + np.cumsum(rng.standard_normal((1 << 14, seeds)), axis=0) * walk * math.sqrt(T) * T)
    result = allan.analyse(increments, T, level)
    for terms, truth in ((result.white, arw), (result.random_walk, walk)):
        resolved = [t for t in terms if t.value is not None]
        assert len(resolved) > 0.8 * seeds
        hits = np.mean([t.lower <= truth <= t.upper for t in resolved])
        assert abs(hits - level) < 3 * math.sqrt(level * (1 - level) / len(resolved)), hits


def test_octave_tau_stop_where_one_second_difference_is_left():
    assert list(octave_factors(1024)) == [1, 2, 4, 8, 16, 32, 64, 128, 256, 512]
    assert list(octave_factors(1023)) == [1, 2, 4, 8, 16, 32, 64, 128, 256]


def test_a_constant_rate_leaves_no_deviation():
    """Zero test: a bias (linear phase) is removed exactly by the second difference."""
    result = allan.analyse(np.full((256, 3), 1e-3 * T), T)
    assert np.all(result.adev < 1e-18)
    assert all(t.value is None for t in result.white + result.bias_instability + result.random_walk)


def test_too_short_a_record_is_one_clear_error():
    with pytest.raises(ValueError, match="15 samples give 3 octaves of tau; the noise terms need at least 4"):
        allan.analyse(np.zeros((15, 3)), T)


def test_bias_instability_floor_factor_is_ieee_952s_0664():
    assert math.sqrt(FLICKER_FLOOR) == pytest.approx(0.664, abs=5e-4)


def test_datasheet_units_follow_from_degrees_and_hours():
    """1 deg/sqrt(h) = (pi/180)/60 rad/sqrt(s) = 60 deg/h/sqrt(Hz); 1 m/s/sqrt(h) = 1/60 m/s/sqrt(s)."""
    assert allan.GYRO_UNITS.white == pytest.approx(math.pi / 180.0 / 60.0)
    assert allan.GYRO_UNITS.white / DEG_PER_H == pytest.approx(60.0)
    assert allan.GYRO_UNITS.random_walk == pytest.approx(math.pi / 180.0 / 3600.0 / 60.0)
    assert allan.ACCEL_UNITS.white == allan.ACCEL_UNITS.random_walk == pytest.approx(1.0 / 60.0)
    assert Term(2.0, 1.0, 4.0).scaled(2.0) == Term(1.0, 0.5, 2.0)


def test_noise_json_has_the_design_keys_in_datasheet_units_and_null_where_unresolved(tmp_path):
    arw_deg_per_sqrt_h, vrw = 0.05, 0.02  # deg/sqrt(h), m/s/sqrt(h)
    gyro = allan.analyse(_white(1 << 12, arw_deg_per_sqrt_h * allan.GYRO_UNITS.white, 3, seed=1), T)
    accel = allan.analyse(_white(1 << 12, vrw * allan.ACCEL_UNITS.white, 3, seed=2), T)
    doc = write_noise(tmp_path, noise_document(gyro, accel), gyro, accel)
    assert json.loads((tmp_path / "noise.json").read_text()) == doc
    assert (tmp_path / "allan.png").stat().st_size > 0
    assert doc["gyro"]["arw_deg_per_sqrt_h"] == pytest.approx([arw_deg_per_sqrt_h] * 3, rel=0.05)
    assert doc["accel"]["vrw_m_per_s_per_sqrt_h"] == pytest.approx([vrw] * 3, rel=0.05)
    assert doc["gyro"]["bias_instability_dph"] == doc["accel"]["rrw_m_per_s2_per_sqrt_h"] == [None] * 3
    assert doc["tau_s"][0] == T and len(doc["adev"]["gyro"]) == 3 and len(doc["adev"]["gyro"][0]) == len(doc["tau_s"])
    # The deviation at tau = 1 s of white noise is N: deg/h at 1 s from deg/sqrt(h) is a factor 60.
    one_second = doc["tau_s"].index(T * 128)
    assert doc["adev"]["gyro"][0][one_second] * math.sqrt(T * 128) / 60.0 == pytest.approx(arw_deg_per_sqrt_h, rel=0.1)
    lower, upper = doc["ci"]["gyro"]["arw_deg_per_sqrt_h"]["lower"], doc["ci"]["gyro"]["arw_deg_per_sqrt_h"]["upper"]
    assert all(lo < v < hi for lo, v, hi in zip(lower, doc["gyro"]["arw_deg_per_sqrt_h"], upper))
    assert doc["duration_s"] == pytest.approx((1 << 12) * T)
    assert list(doc["gyro"]) == ["quantization_urad", "arw_deg_per_sqrt_h", "bias_instability_dph",
                                 "rrw_deg_per_h_per_sqrt_h", "ramp_dph_per_h"]
    assert list(doc["accel"]) == ["quantization_m_per_s", "vrw_m_per_s_per_sqrt_h", "bias_instability_ug",
                                  "rrw_m_per_s2_per_sqrt_h", "ramp_ug_per_h"]
    nulls = {f"{s}.{key}.{k}" for s in ("gyro", "accel") for key, v in doc[s].items() for k in range(3) if v[k] is None}
    assert set(doc["unresolved"]) == nulls and "gyro.bias_instability_dph.0" in nulls
    assert all(reason.startswith(("consistent with zero", "out of the non-negative fit"))
               for reason in doc["unresolved"].values())
    page = noise_section(doc)
    assert "rate / acceleration ramp" in page and "deg/h/h" in page and "µrad" in page
    assert "not resolved (1)" in page and f"(1) {doc['unresolved']['gyro.bias_instability_dph.0']}" in page


def test_linear_detrend_removes_a_ramp_exactly_and_keeps_the_gaps():
    rate = 2e-3 + 3e-5 * (np.arange(1000) + 0.5) * T  # rad/s: a bias and a ramp of 3e-5 rad/s^2
    increments = np.column_stack([rate * T, -rate * T])
    increments[100:110] = np.nan
    residual, slope = linear_trend(increments, T)
    np.testing.assert_allclose(slope, [3e-5, -3e-5], rtol=1e-9)
    assert np.isnan(residual[100:110]).all() and not np.isnan(residual[:100]).any()
    present = ~np.isnan(residual[:, 0])
    assert np.ptp(residual[present, 0]) < 1e-15  # the bias left, constant
    assert [build_parser().parse_args(["noise", "r.csv", "--detrend", d]).detrend for d in DETRENDS] == list(DETRENDS)
