"""Overlapping Allan deviation of increments and the IEEE Std 952 / 1293 noise terms with intervals.

The increments of a sensor (angle increments of a gyro, velocity increments of an accelerometer) are
summed into the "phase" x_k = sum_{i<=k} dx_i, x_0 = 0 (no rate is differentiated). With N = n + 1
phase points at period T, the overlapping Allan variance at tau = m T is (NIST SP 1065, Eq. 14)

    avar(tau) = sum_{i=0}^{N-2m-1} (x_{i+2m} - 2 x_{i+m} + x_i)^2 / (2 tau^2 (N - 2m)),

at octave-spaced m = 1, 2, 4, ... with N - 2m >= 1. Its unit is the rate's squared (rad^2/s^2, m^2/s^4).

Noise model (IEEE Std 952-1997, Annex C, Eqs. C.11, C.15, C.17; Std 1293-1998 the same for accelerometers):

    avar(tau) = N^2 / tau  +  (2 ln 2 / pi) B^2  +  K^2 tau / 3,

N the white-rate coefficient (angle / velocity random walk), B the bias instability (the flat floor of
the deviation is 0.664 B), K the rate (acceleration) random walk. In the power-law notation of
frequency metrology the rate is the "frequency": white rate is white FM (alpha = 0), bias instability
flicker FM (alpha = -1), random walk RW FM (alpha = -2).

Equivalent degrees of freedom: NIST SP 1065 Table 5 (Howe, Allan, Barnes 1981; Stable32's "simple"
EDF for the overlapping Allan variance), see ``edf``. Where several terms contribute at one tau the EDF
is the mixture of ``mixed_edf``: a lower bound on the true EDF, so the intervals err on the wide side.
Intervals are chi-square (SP 1065 Eq. 68): nu avar / chi2_{nu}((1 + p) / 2) <= AVAR <= nu avar /
chi2_{nu}((1 - p) / 2).

The terms come from one non-negative fit of the model to the Allan variances, each weighted by its
inverse variance 2 AVAR^2 / nu with AVAR and nu from the model itself (iterated to convergence), see
``fit_terms``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from hil.units import DEG_PER_H, DEG_PER_H_PER_SQRT_H, DEG_PER_SQRT_H, PER_SQRT_H, UG

Noise = Literal["white", "flicker", "random_walk"]
NOISES: tuple[Noise, ...] = ("white", "flicker", "random_walk")
FLICKER_FLOOR = 2.0 * math.log(2.0) / math.pi  # avar floor / B^2 (IEEE 952 Eq. C.15); sqrt: 0.664
DEFAULT_LEVEL = 0.683  # two-sided, the "1-sigma" intervals of Stable32
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
    edf: np.ndarray  # (M, K), from the fitted model's mixture of noise types
    model_adev: np.ndarray  # (M, K), the fitted model
    white: tuple[Term, ...]
    bias_instability: tuple[Term, ...]
    random_walk: tuple[Term, ...]
    level: float
    duration_s: float


@dataclass(frozen=True)
class TermUnits:
    """SI per datasheet unit of each term and of the deviation, for ``Term.scaled``."""

    white: float
    bias_instability: float
    random_walk: float
    adev: float


GYRO_UNITS = TermUnits(DEG_PER_SQRT_H, DEG_PER_H, DEG_PER_H_PER_SQRT_H, DEG_PER_H)  # deg/sqrt(h), deg/h
ACCEL_UNITS = TermUnits(PER_SQRT_H, UG, PER_SQRT_H, UG)  # m/s/sqrt(h), ug, m/s^2/sqrt(h), ug


def octave_factors(n_samples: int) -> np.ndarray:
    """Averaging factors m = 1, 2, 4, ... with at least one second difference (2m <= n_samples)."""
    return 2 ** np.arange(max(int(n_samples).bit_length() - 1, 0))


def overlapping_avar(increments: np.ndarray, period: float, factors: np.ndarray) -> np.ndarray:
    """Overlapping Allan variance (SP 1065 Eq. 14) of increments (n, K) at tau = m period: (M, K)."""
    dx = np.asarray(increments, dtype=float)
    # The mean increment is a linear phase, which the second difference removes exactly; taking it out
    # first keeps the running sum small, so that long records keep their precision.
    x = np.vstack([np.zeros((1,) + dx.shape[1:]), np.cumsum(dx - dx.mean(axis=0), axis=0)])
    out = np.empty((len(factors),) + dx.shape[1:])
    for j, m in enumerate(factors):
        d = x[2 * m :] - 2.0 * x[m:-m] + x[: -2 * m]
        out[j] = np.mean(d * d, axis=0) / (2.0 * (m * period) ** 2)
    return out


def edf(noise: Noise, n_phase: int, m: np.ndarray) -> np.ndarray:
    """EDF of the overlapping Allan variance, N phase points, factor m (NIST SP 1065 Table 5).

    white (white FM): [3(N-1)/(2m) - 2(N-2)/N] 4m^2/(4m^2+5); flicker (flicker FM): 2(N-2)^2/(2.3N-4.9)
    at m = 1, 5N^2/(4m(N+3m)) above; random_walk (RW FM): (N-2)/m [(N-1)^2 - 3m(N-1) + 4m^2]/(N-3)^2.
    """
    n = float(n_phase)
    m = np.asarray(m, dtype=float)
    if noise == "white":
        return (3.0 * (n - 1.0) / (2.0 * m) - 2.0 * (n - 2.0) / n) * 4.0 * m**2 / (4.0 * m**2 + 5.0)
    if noise == "flicker":
        return np.where(m == 1, 2.0 * (n - 2.0) ** 2 / (2.3 * n - 4.9), 5.0 * n**2 / (4.0 * m * (n + 3.0 * m)))
    if noise == "random_walk":
        return (n - 2.0) / m * ((n - 1.0) ** 2 - 3.0 * m * (n - 1.0) + 4.0 * m**2) / (n - 3.0) ** 2
    raise ValueError(f"unknown noise type {noise!r}: expected one of {NOISES}")


def mixed_edf(parts: np.ndarray, edfs: np.ndarray) -> np.ndarray:
    """EDF where independent noises with Allan variances parts (M, 3) and EDFs edfs (M, 3) add.

    1/sqrt(nu) = sum_i (A_i / A) / sqrt(nu_i): since var(avar-hat) = 2 tr((Q S)^2) for the estimator's
    quadratic form Q and a covariance S = sum_i S_i, Cauchy-Schwarz gives sd <= sum_i sd_i, so this
    nu is a lower bound (intervals no narrower than the data allow).
    """
    total = parts.sum(axis=1)
    return total**2 / np.sum(parts / np.sqrt(edfs), axis=1) ** 2


def chi2_interval(avar: np.ndarray, nu: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided interval of a variance estimated with nu degrees of freedom (SP 1065 Eq. 68)."""
    from scipy import stats  # here, not with the module: 0.5 s of start-up for every trial's report

    return (
        nu * avar / stats.chi2.ppf(0.5 + level / 2.0, nu),
        nu * avar / stats.chi2.ppf(0.5 - level / 2.0, nu),
    )


@dataclass(frozen=True)
class TermFit:
    """The fitted coefficients of ``fit_terms`` and what they were weighted with."""

    coefficients: np.ndarray  # (3,): N^2, B^2, K^2
    sd: np.ndarray  # (3,): bound on their standard deviations
    edf: np.ndarray  # (M,)
    model: np.ndarray  # (M,)


def fit_terms(tau: np.ndarray, avar: np.ndarray, n_phase: int, m: np.ndarray) -> TermFit:
    """Non-negative weighted least-squares fit of N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 to avar (M,).

    Weights nu / (2 AVAR^2), the inverse variance of each estimate, with AVAR and nu (``mixed_edf``) from
    the current model, iterated to a fixed point. Linear in (N^2, B^2, K^2), so the standard deviation
    of each coefficient is bounded by sum_j |G_ij| sd_j, G the weighted pseudo-inverse and sd_j =
    AVAR_j sqrt(2 / nu_j): a bound that holds whatever the correlation between the overlapping estimates.
    """
    from scipy import optimize  # here, not with the module: see chi2_interval

    design = np.column_stack([1.0 / tau, np.full_like(tau, FLICKER_FLOOR), tau / 3.0])
    edfs = np.column_stack([edf(noise, n_phase, m) for noise in NOISES])
    if not np.any(avar > 0.0):
        return TermFit(np.zeros(3), np.zeros(3), edfs[:, 0], np.zeros_like(avar))
    model, nu = np.maximum(avar, avar[avar > 0.0].min()), edfs[:, 0]
    for _ in range(_MAX_ITERATIONS):
        root_w = np.sqrt(nu / 2.0) / model
        coefficients = optimize.nnls(design * root_w[:, None], avar * root_w)[0]
        parts = design * coefficients
        new_model = parts.sum(axis=1)
        nu = mixed_edf(parts, edfs)
        converged = np.allclose(new_model, model, rtol=1e-10, atol=0.0)
        model = new_model
        if converged:
            break
    active = coefficients > 0.0
    weighted = design[:, active] * root_w[:, None]
    pseudo_inverse = np.linalg.pinv(weighted) * root_w  # G: coefficients = G avar
    sd = np.zeros(3)
    sd[active] = np.abs(pseudo_inverse) @ (model * np.sqrt(2.0 / nu))
    return TermFit(coefficients, sd, nu, model)


def _term(coefficient: float, sd: float, level: float) -> Term:
    """sqrt(coefficient) and its interval at ``level``, or None when the record cannot resolve it.

    Rule: unresolved when coefficient <= sd, its standard deviation (bound), i.e. fewer than 2 EDF.
    Otherwise the interval is chi-square with nu = 2 (coefficient / sd)^2, the EDF of a variance with
    that spread.
    """
    if not coefficient > sd:
        return Term(None, None, None)
    lo, hi = chi2_interval(coefficient, 2.0 * (coefficient / sd) ** 2, level)
    return Term(*(math.sqrt(float(v)) for v in (coefficient, lo, hi)))


def analyse(increments: np.ndarray, period: float, level: float = DEFAULT_LEVEL) -> AllanAnalysis:
    """Allan deviation at octave tau with intervals, and the fitted terms, of increments (n, K) or (n,).

    ``period`` the sample interval in s; ``level`` the two-sided level of every interval.
    """
    dx = np.asarray(increments, dtype=float)
    dx = dx[:, None] if dx.ndim == 1 else dx
    n = len(dx)
    if not period > 0.0:
        raise ValueError(f"the sample period must be positive, got {period}")
    factors = octave_factors(n)
    if len(factors) < _MIN_OCTAVES:
        raise ValueError(
            f"{n} samples give {len(factors)} octaves of tau; the noise terms need at least {_MIN_OCTAVES} "
            f"({2 ** _MIN_OCTAVES} samples): record a longer trial"
        )
    tau = factors * period
    avar = overlapping_avar(dx, period, factors)
    fits = [fit_terms(tau, avar[:, k], n + 1, factors) for k in range(dx.shape[1])]
    nu = np.column_stack([f.edf for f in fits])
    lower, upper = chi2_interval(avar, nu, level)
    white, flicker, walk = (tuple(_term(f.coefficients[i], f.sd[i], level) for f in fits) for i in range(3))
    return AllanAnalysis(
        tau=tau,
        adev=np.sqrt(avar),
        lower=np.sqrt(lower),
        upper=np.sqrt(upper),
        edf=nu,
        model_adev=np.sqrt(np.column_stack([f.model for f in fits])),
        white=white,
        bias_instability=flicker,
        random_walk=walk,
        level=level,
        duration_s=n * period,
    )
