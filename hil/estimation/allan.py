"""Overlapping Allan deviation of increments and the IEEE Std 952 / 1293 noise terms with intervals.

The increments of a sensor (angle increments of a gyro, velocity increments of an accelerometer) are
summed into the "phase" x_k = sum_{i<=k} dx_i, x_0 = 0 (no rate is differentiated). With N = n + 1
phase points at period T, the overlapping Allan variance at tau = m T is (NIST SP 1065, Eq. 14)

    avar(tau) = sum_{i=0}^{N-2m-1} (x_{i+2m} - 2 x_{i+m} + x_i)^2 / (2 tau^2 (N - 2m)),

at the m of a grid (``allan_taus``: octave, decade, all, or a list) with N - 2m >= 1. Its unit is the
rate's squared (rad^2/s^2, m^2/s^4). A missing sample (a NaN row, a gap) leaves out every difference
that spans it; the count left is the M of the EDF.

Intervals at each tau: the noise type identified there as Stable32 does (``allan_noise_id``: lag-1
autocorrelation, B1 ratio and R(n)), Greenhall's EDF nu for it (``allan_edf``), and chi-square (SP 1065 Eq. 68):
nu avar / chi2_{nu}((1 + p) / 2) <= AVAR <= nu avar / chi2_{nu}((1 - p) / 2).

IEEE Std 952's five terms (quantisation Q, white rate N, bias instability B, rate random walk K, rate
ramp R) come from one non-negative fit of its model to the Allan variances at octave tau, weighted by
the model's own standard deviations and iterated; their intervals from the fit's covariance with the
estimates' full covariance (``allan_cov``), see ``allan_fit``. docs/noise.md has the derivation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.estimation.allan_cov import noise_products
from hil.estimation.allan_edf import greenhall_edf
from hil.estimation.allan_fit import (
    REASON_REMOVED,
    RESOLVED_AT,
    TERM_NAMES,
    Term,
    design_matrix,
    fit_terms,
    term,
)
from hil.estimation.allan_noise_id import identify
from hil.estimation.allan_taus import octave_factors, tau_factors
from hil.units import DEG_PER_H, DEG_PER_H_PER_SQRT_H, DEG_PER_SQRT_H, HOUR, PER_SQRT_H, UG

URAD = 1e-6  # rad per microradian
DEFAULT_LEVEL = 0.683  # two-sided, the "1-sigma" intervals of Stable32
MAX_MISSING = 0.1  # a record with more of its samples in gaps is refused
_MIN_OCTAVES = 4  # fewer tau than this cannot separate the terms


@dataclass(frozen=True)
class AllanAnalysis:
    """Allan deviation of K columns of increments (one per axis) and their fitted noise terms.

    Rates in the increments' unit per second (rad/s or m/s^2). ``quantization`` is Q (rad, m/s), ``white``
    N (rad/sqrt(s), m/s/sqrt(s)), ``bias_instability`` B (rad/s, m/s^2), ``random_walk`` K (rad/s/sqrt(s),
    m/s^2/sqrt(s)), ``ramp`` R (rad/s^2, m/s^3), one Term per column.
    """

    tau: np.ndarray  # (M,) s
    adev: np.ndarray  # (M, K)
    lower: np.ndarray  # (M, K), interval at ``level``
    upper: np.ndarray  # (M, K)
    edf: np.ndarray  # (M, K), Greenhall's for the noise type identified at each tau
    alpha: np.ndarray  # (M, K), that noise type's exponent: 2 white PM, 1 flicker PM, 0 white, -1 flicker, -2 walk
    model_adev: np.ndarray  # (M, K), the fitted model
    quantization: tuple[Term, ...]
    white: tuple[Term, ...]
    bias_instability: tuple[Term, ...]
    random_walk: tuple[Term, ...]
    ramp: tuple[Term, ...]
    level: float
    duration_s: float
    missing: int  # samples missing in gaps


@dataclass(frozen=True)
class TermUnits:
    """SI per datasheet unit of each term and of the deviation, for ``Term.scaled``."""

    quantization: float
    white: float
    bias_instability: float
    random_walk: float
    ramp: float
    adev: float


# IEEE 952's units: urad, deg/sqrt(h), deg/h, deg/h/sqrt(h), deg/h/h; the deviation in deg/h
GYRO_UNITS = TermUnits(URAD, DEG_PER_SQRT_H, DEG_PER_H, DEG_PER_H_PER_SQRT_H, DEG_PER_H / HOUR, DEG_PER_H)
# Std 1293's: m/s, m/s/sqrt(h), ug, m/s^2/sqrt(h), ug/h; the deviation in ug
ACCEL_UNITS = TermUnits(1.0, PER_SQRT_H, UG, PER_SQRT_H, UG / HOUR, UG)


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
            taus: str | tuple[float, ...] = "octave", removed: tuple[str, ...] = ()) -> AllanAnalysis:
    """Allan deviation on the ``taus`` grid (``allan_taus``) with intervals, and the terms fitted over the
    octave tau, of increments (n, K) or (n,); rows with NaN are missing samples (gaps).

    ``period`` the sample interval in s; ``level`` the two-sided level of every interval; ``removed`` the
    terms (of TERM_NAMES) taken out of the increments before (``allan_detrend``): not fitted, null.
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
    fits = [fit_terms(fit_factors * period, avar_fit[:, k], products, removed) for k in range(dx.shape[1])]
    factors = fit_factors if taus == "octave" else tau_factors(taus, n, period)
    avar, counts = (avar_fit, fit_counts) if taus == "octave" else overlapping_avar(dx, period, factors)
    factors, avar, counts = factors[counts > 0], avar[counts > 0], counts[counts > 0]
    tau = factors * period
    parts = [design_matrix(tau) * f.coefficients for f in fits]
    alpha = identify(dx, factors)
    nu = _edfs(alpha, factors, counts)
    lower, upper = chi2_interval(avar, nu, level)
    reported = [f.reported() for f in fits]
    gone = Term(None, None, None, REASON_REMOVED)
    terms = {name: tuple(gone if name in removed else term(c[i], s[i], level, RESOLVED_AT[i]) for c, s in reported)
             for i, name in enumerate(TERM_NAMES)}
    return AllanAnalysis(
        tau=tau,
        adev=np.sqrt(avar),
        lower=np.sqrt(lower),
        upper=np.sqrt(upper),
        edf=nu,
        alpha=alpha,
        model_adev=np.sqrt(np.column_stack([p.sum(axis=1) for p in parts])),
        level=level,
        duration_s=n * period,
        missing=missing,
        **terms,
    )
