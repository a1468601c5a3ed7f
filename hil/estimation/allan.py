"""Overlapping Allan deviation of increments and the IEEE Std 952 / 1293 noise terms with intervals.

The increments of a sensor (angle increments of a gyro, velocity increments of an accelerometer) are
summed into the "phase" x_k = sum_{i<=k} dx_i, x_0 = 0 (no rate is differentiated). With N = n + 1
phase points at period T, the overlapping Allan variance at tau = m T is (NIST SP 1065, Eq. 14)

    avar(tau) = sum_{i=0}^{N-2m-1} (x_{i+2m} - 2 x_{i+m} + x_i)^2 / (2 tau^2 (N - 2m)),

at the m of a grid (``allan_taus``: octave, decade, all, or a list) with N - 2m >= 1. Its unit is the
rate's squared (rad^2/s^2, m^2/s^4). A missing sample (a NaN row, a gap) leaves out every difference
that spans it; the count left is the M of the EDF.

Noise model (IEEE Std 952-1997, Annex C, Eqs. C.11, C.15, C.17; Std 1293-1998 the same for accelerometers):

    avar(tau) = N^2 / tau  +  (2 ln 2 / pi) B^2  +  K^2 tau / 3,

N the white-rate coefficient (angle / velocity random walk), B the bias instability (the flat floor of
the deviation is 0.664 B), K the rate (acceleration) random walk. In the power-law notation of
frequency metrology the rate is the "frequency": white rate is white FM (alpha = 0), bias instability
flicker FM (alpha = -1), random walk RW FM (alpha = -2).

Intervals at each tau: the noise type identified there as Stable32 does (``allan_noise_id``: lag-1
autocorrelation, B1 ratio and R(n)), Greenhall's EDF nu for it (``allan_edf``), and chi-square (SP 1065 Eq. 68):
nu avar / chi2_{nu}((1 + p) / 2) <= AVAR <= nu avar / chi2_{nu}((1 - p) / 2).

The terms come from one non-negative fit of the model to the Allan variances at octave tau, weighted by
the model's own standard deviations and iterated; their intervals from the fit's covariance with the
estimates' full covariance (``allan_cov``), see ``fit_terms``. docs/noise.md has the derivation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.estimation.allan_cov import avar_covariance, noise_products
from hil.estimation.allan_edf import greenhall_edf
from hil.estimation.allan_noise_id import identify
from hil.estimation.allan_taus import octave_factors, tau_factors
from hil.units import DEG_PER_H, DEG_PER_H_PER_SQRT_H, DEG_PER_SQRT_H, PER_SQRT_H, UG

FLICKER_FLOOR = 2.0 * math.log(2.0) / math.pi  # avar floor / B^2 (IEEE 952 Eq. C.15); sqrt: 0.664
DEFAULT_LEVEL = 0.683  # two-sided, the "1-sigma" intervals of Stable32
MAX_MISSING = 0.1  # a record with more of its samples in gaps is refused
_MIN_OCTAVES = 4  # fewer tau than this cannot separate three terms
_MAX_ITERATIONS = 100


@dataclass(frozen=True)
class Term:
    """One fitted noise coefficient and its two-sided interval; all None when the fit cannot resolve it."""

    value: float | None
    lower: float | None
    upper: float | None

    def scaled(self, unit: float) -> Term:
        """The same term in another unit: each figure divided by ``unit`` (SI per that unit)."""
        return Term(*(None if v is None else v / unit for v in (self.value, self.lower, self.upper)))


@dataclass(frozen=True)
class AllanAnalysis:
    """Allan deviation of K columns of increments (one per axis) and their fitted noise terms.

    Rates in the increments' unit per second (rad/s or m/s^2). ``white`` is N (rad/sqrt(s),
    m/s/sqrt(s)), ``bias_instability`` B (rad/s, m/s^2), ``random_walk`` K (rad/s/sqrt(s),
    m/s^2/sqrt(s)), one Term per column.
    """

    tau: np.ndarray  # (M,) s
    adev: np.ndarray  # (M, K)
    lower: np.ndarray  # (M, K), interval at ``level``
    upper: np.ndarray  # (M, K)
    edf: np.ndarray  # (M, K), Greenhall's for the noise type identified at each tau
    alpha: np.ndarray  # (M, K), that noise type's exponent: 2 white PM, 1 flicker PM, 0 white, -1 flicker, -2 walk
    model_adev: np.ndarray  # (M, K), the fitted model
    white: tuple[Term, ...]
    bias_instability: tuple[Term, ...]
    random_walk: tuple[Term, ...]
    level: float
    duration_s: float
    missing: int  # samples missing in gaps


@dataclass(frozen=True)
class TermUnits:
    """SI per datasheet unit of each term and of the deviation, for ``Term.scaled``."""

    white: float
    bias_instability: float
    random_walk: float
    adev: float


GYRO_UNITS = TermUnits(DEG_PER_SQRT_H, DEG_PER_H, DEG_PER_H_PER_SQRT_H, DEG_PER_H)  # deg/sqrt(h), deg/h
ACCEL_UNITS = TermUnits(PER_SQRT_H, UG, PER_SQRT_H, UG)  # m/s/sqrt(h), ug, m/s^2/sqrt(h), ug


def overlapping_avar(increments: np.ndarray, period: float, factors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan variance (SP 1065 Eq. 14) of increments (n, K) at tau = m period: (M, K), and the
    count of second differences at each m, (M,). A row with a NaN is a missing sample: the differences
    that span it are left out (Eq. 14's mean taken over the others; a tau with none left gives NaN)."""
    dx = np.asarray(increments, dtype=float)
    dx = dx[:, None] if dx.ndim == 1 else dx
    missing = np.isnan(dx).any(axis=1)
    # The mean increment is a linear phase, which the second difference removes exactly; taking it out
    # first keeps the running sum small, so that long records keep their precision.
    centred = np.where(missing[:, None], 0.0, dx - np.nanmean(dx[~missing], axis=0) if (~missing).any() else 0.0)
    x = np.vstack([np.zeros((1,) + dx.shape[1:]), np.cumsum(centred, axis=0)])
    gaps = np.concatenate([[0], np.cumsum(missing)])
    out, counts = np.full((len(factors),) + dx.shape[1:], np.nan), np.zeros(len(factors), dtype=int)
    for j, m in enumerate(factors):
        d = x[2 * m :] - 2.0 * x[m:-m] + x[: -2 * m]
        whole = gaps[2 * m :] == gaps[: -2 * m]
        counts[j] = int(np.count_nonzero(whole))
        if counts[j]:
            d = d[whole] if counts[j] < len(d) else d
            out[j] = np.mean(d * d, axis=0) / (2.0 * (m * period) ** 2)
    return out, counts


def chi2_interval(avar: np.ndarray, nu: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided interval of a variance estimated with nu degrees of freedom (SP 1065 Eq. 68)."""
    from scipy import stats  # here, not with the module: 0.5 s of start-up for every trial's report

    return (
        nu * avar / stats.chi2.ppf(0.5 + level / 2.0, nu),
        nu * avar / stats.chi2.ppf(0.5 - level / 2.0, nu),
    )


@dataclass(frozen=True)
class TermFit:
    """The fitted coefficients of ``fit_terms``, their covariance, and the model they give."""

    coefficients: np.ndarray  # (3,): N^2, B^2, K^2
    covariance: np.ndarray  # (3, 3)
    model: np.ndarray  # (M,) Allan variance of the fitted model
    parts: np.ndarray  # (M, 3): what each term contributes to it


def design_matrix(tau: np.ndarray) -> np.ndarray:
    """(M, 3): the Allan variance per unit N^2, B^2, K^2 at ``tau`` (IEEE 952 Eqs. C.11, C.15, C.17)."""
    return np.column_stack([1.0 / tau, np.full_like(tau, FLICKER_FLOOR), tau / 3.0])


def fit_terms(tau: np.ndarray, avar: np.ndarray, products: np.ndarray) -> TermFit:
    """Non-negative weighted least-squares fit of N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 to avar (M,).

    Each estimate is weighted by its inverse standard deviation under the current model (``allan_cov``
    with the ``products`` of the tau), iterated to a fixed point. The coefficients are G avar, G the
    weighted pseudo-inverse of the active terms, so their covariance is G C G^T with C the full covariance
    of the estimates under the fitted model: their correlation over neighbouring tau counted, not bounded.
    """
    from scipy import optimize  # here, not with the module: see chi2_interval

    design = design_matrix(tau)
    coefficients = np.zeros(3)
    if not np.any(avar > 0.0):
        return TermFit(coefficients, np.zeros((3, 3)), np.zeros_like(avar), np.zeros_like(design))
    parts = np.column_stack([np.maximum(avar, avar[avar > 0.0].min()), np.zeros((len(avar), 2))])
    for _ in range(_MAX_ITERATIONS):
        root_w = 1.0 / np.sqrt(np.diag(avar_covariance(products, parts)))
        new = optimize.nnls(design * root_w[:, None], avar * root_w)[0]
        converged = np.allclose(new, coefficients, rtol=1e-10, atol=0.0)
        coefficients, parts = new, design * new
        if converged or not np.any(new > 0.0):
            break
    covariance = np.zeros((3, 3))
    active = coefficients > 0.0
    if active.any():
        full = avar_covariance(products, parts)
        root_w = 1.0 / np.sqrt(np.diag(full))
        pseudo_inverse = np.linalg.pinv(design[:, active] * root_w[:, None]) * root_w  # G
        covariance[np.ix_(active, active)] = pseudo_inverse @ full @ pseudo_inverse.T
        for q in np.flatnonzero(~active):  # a term out of the fit: its variance were it in, for its upper limit
            with_q = active.copy()
            with_q[q] = True
            g = np.linalg.pinv(design[:, with_q] * root_w[:, None]) * root_w
            row = int(np.count_nonzero(with_q[:q]))
            covariance[q, q] = (g @ full @ g.T)[row, row]
    return TermFit(coefficients, covariance, parts.sum(axis=1), parts)


def _term(coefficient: float, sd: float, level: float) -> Term:
    """sqrt(coefficient) and its interval at ``level``; the value None when the record cannot resolve it.

    The interval is the normal one, coefficient -/+ z sd (z the two-sided normal quantile of ``level``),
    cut at zero, then the square root: the coefficient is a weighted sum of many estimates with weights of
    both signs, not one chi-square variance (docs/noise.md). It is given also where the value is not:
    unresolved when coefficient <= sd (consistent with zero), and then the interval is the upper limit a
    lab quotes; for a term out of the non-negative fit (coefficient 0), [0, sqrt(z sd)] with sd its
    standard deviation were it in. A record without noise (sd 0) has neither.
    """
    from scipy import stats  # here, not with the module: see chi2_interval

    if not sd > 0.0:
        return Term(None, None, None)
    z = float(stats.norm.ppf(0.5 + level / 2.0))
    lower, upper = (math.sqrt(max(v, 0.0)) for v in (coefficient - z * sd, coefficient + z * sd))
    return Term(math.sqrt(coefficient) if coefficient > sd else None, lower, upper)


def _edfs(alpha: np.ndarray, factors: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Greenhall's EDF at each tau and axis (M, K), from M = counts differences; the axes mostly share a
    noise type, so each sum is taken once."""
    known: dict[tuple[int, int], float] = {}
    out = np.empty(alpha.shape)
    for j, (m, count) in enumerate(zip(factors, counts)):
        for k, a in enumerate(alpha[j]):
            key = (int(a), int(m))
            if key not in known:
                known[key] = greenhall_edf(key[0], key[1], int(count) + 2 * key[1])
            out[j, k] = known[key]
    return out


def analyse(increments: np.ndarray, period: float, level: float = DEFAULT_LEVEL,
            taus: str | tuple[float, ...] = "octave") -> AllanAnalysis:
    """Allan deviation on the ``taus`` grid (``allan_taus``) with intervals, and the terms fitted over the
    octave tau, of increments (n, K) or (n,); rows with NaN are missing samples (gaps).

    ``period`` the sample interval in s; ``level`` the two-sided level of every interval.
    """
    dx = np.asarray(increments, dtype=float)
    dx = dx[:, None] if dx.ndim == 1 else dx
    n = len(dx)
    if not period > 0.0:
        raise ValueError(f"the sample period must be positive, got {period}")
    fit_factors = octave_factors(n)
    if len(fit_factors) < _MIN_OCTAVES:
        raise ValueError(
            f"{n} samples give {len(fit_factors)} octaves of tau; the noise terms need at least {_MIN_OCTAVES} "
            f"({2 ** _MIN_OCTAVES} samples): record a longer trial"
        )
    missing = int(np.count_nonzero(np.isnan(dx).any(axis=1)))
    if missing > MAX_MISSING * n:
        raise ValueError(f"{missing} of {n} samples ({missing / n:.1%}) are missing in gaps, more than the "
                         f"{MAX_MISSING:.0%} the analysis takes: analyse the stretches between the gaps")
    avar_fit, fit_counts = overlapping_avar(dx, period, fit_factors)
    kept = fit_counts > 0
    fit_factors, avar_fit, fit_counts = fit_factors[kept], avar_fit[kept], fit_counts[kept]
    products = noise_products(fit_factors, fit_counts)
    fits = [fit_terms(fit_factors * period, avar_fit[:, k], products) for k in range(dx.shape[1])]
    factors = fit_factors if taus == "octave" else tau_factors(taus, n, period)
    avar, counts = (avar_fit, fit_counts) if taus == "octave" else overlapping_avar(dx, period, factors)
    factors, avar, counts = factors[counts > 0], avar[counts > 0], counts[counts > 0]
    tau = factors * period
    parts = [design_matrix(tau) * f.coefficients for f in fits]
    alpha = identify(dx, factors)
    nu = _edfs(alpha, factors, counts)
    lower, upper = chi2_interval(avar, nu, level)
    sd = [np.sqrt(np.diag(f.covariance)) for f in fits]
    white, flicker, walk = (tuple(_term(f.coefficients[i], s[i], level) for f, s in zip(fits, sd)) for i in range(3))
    return AllanAnalysis(
        tau=tau,
        adev=np.sqrt(avar),
        lower=np.sqrt(lower),
        upper=np.sqrt(upper),
        edf=nu,
        alpha=alpha,
        model_adev=np.sqrt(np.column_stack([p.sum(axis=1) for p in parts])),
        white=white,
        bias_instability=flicker,
        random_walk=walk,
        level=level,
        duration_s=n * period,
        missing=missing,
    )
