"""EDF of the overlapping Allan variance by Greenhall's general algorithm, and the noise type at each tau.

C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite differences", 35th
PTTI (2003), for the second difference (d = 2), the overlapping estimator (stride S = m) of the unmodified
variance (filter factor F = m) and the power-law FM noises the IEEE model holds: alpha = 0 (white rate),
-1 (flicker: bias instability), -2 (random walk). Time t is in units of tau.

    sw(t): -|t| (alpha 2), t^2 ln|t| (1), |t|^3 (0), -t^4 ln|t| (-1), -|t|^5 (-2)           (Eq. 7)
    sx(t) = F^2 [2 sw(t) - sw(t - 1/F) - sw(t + 1/F)], sw(t; alpha + 2) for F = infinity    (Eq. 8)
    sz(t) = 6 sx(t) - 4 sx(t - 1) - 4 sx(t + 1) + sx(t - 2) + sx(t + 2)                       (Eq. 9)
    BasicSum(J, M, S) = sz(0)^2 + (1 - J/M) sz(J/S)^2 + 2 sum_{j=1}^{J-1} (1 - j/M) sz(j/S)^2  (Eq. 10)

sz(t) is (proportional to) the covariance of two second differences t tau apart, so 1 / EDF = BasicSum /
(M sz(0)^2) is 2 var(avar) / avar^2 with the sum cut at J = min(M, 3S), past which the differences share
no sample. F is infinity here: the phase of summed increments is the rate's exact integral at the sample
times, not a phase averaged over T (F = m, a counter's); the sums then equal the exact EDF of white-rate
noise at every m (tests). With N phase points, M = N - 2m differences and r = M / m: J <= 100 sums
directly; beyond, 1 / EDF = (a0 - a1 / r) / r from Greenhall's Table 2 when r > 3, else BasicSum(100, 100,
100 / r).

The noise type at a tau is W. J. Riley's lag-1 autocorrelation identification (NIST SP 1065 section 5.6):
the phase decimated by m, its quadratic trend removed, differenced d times until rho = r1 / (1 + r1) < 0.25
(r1 the lag-1 autocorrelation) or d = 2; then alpha = round(-2 rho) - 2 d + 2. It needs 30 points.
"""

from __future__ import annotations

import math

import numpy as np

J_MAX = 100
MIN_POINTS = 30  # decimated phase points the lag-1 identification needs
ALPHAS = (0, -1, -2)  # white rate, bias instability (flicker), random walk
# Greenhall and Riley Table 2, d = 2: (a0, a1) per alpha of the unmodified variances
_TABLE2 = {0: (2.0 / 3.0, 1.0 / 3.0), -1: (0.852, 0.375), -2: (1.079, 0.368)}
_D = 2


def sw(t: np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall's sw(t) (Eq. 7), 0 ln 0 taken as 0."""
    t = np.abs(np.asarray(t, dtype=float))
    if alpha == 2:
        return -t
    if alpha == 0:
        return t**3
    if alpha == -2:
        return -(t**5)
    log = np.log(np.where(t > 0.0, t, 1.0))
    if alpha == 1:
        return t**2 * log
    if alpha == -1:
        return -(t**4) * log
    raise ValueError(f"noise exponent alpha = {alpha} is outside 2..-2")


def sx(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Greenhall's sx(t) (Eq. 8): the phase's generalised autocovariance with rates averaged over tau / F."""
    if math.isinf(f):
        return sw(t, alpha + 2)
    return f * f * (2.0 * sw(t, alpha) - sw(t - 1.0 / f, alpha) - sw(t + 1.0 / f, alpha))


def sz(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Greenhall's sz(t) for d = 2 (Eq. 9): the covariance of second differences t tau apart (to a factor)."""
    return (6.0 * sx(t, f, alpha) - 4.0 * (sx(t - 1.0, f, alpha) + sx(t + 1.0, f, alpha))
            + sx(t - 2.0, f, alpha) + sx(t + 2.0, f, alpha))


def basic_sum(j_cut: int, m_count: float, stride: float, f: float, alpha: int) -> float:
    """Greenhall's BasicSum (Eq. 10)."""
    j = np.arange(1, j_cut)
    body = 2.0 * np.sum((1.0 - j / m_count) * sz(j / stride, f, alpha) ** 2)
    return float(sz(0.0, f, alpha) ** 2 + (1.0 - j_cut / m_count) * sz(j_cut / stride, f, alpha) ** 2 + body)


def greenhall_edf(alpha: int, m: int, n_phase: int) -> float:
    """EDF of the overlapping Allan variance at factor m from n_phase phase points, noise exponent alpha."""
    m_count = n_phase - 2 * m  # M: second differences (Eq. 11 with L = 2m + 1, S = F = m)
    if m_count < 1:
        raise ValueError(f"factor {m} leaves no second difference in {n_phase} phase points")
    j_cut, r = min(m_count, (_D + 1) * m), m_count / m
    if j_cut <= J_MAX:
        inverse = basic_sum(j_cut, m_count, m, math.inf, alpha) / (float(sz(0.0, math.inf, alpha)) ** 2 * m_count)
    elif r > _D + 1:
        a0, a1 = _TABLE2[alpha]
        inverse = (a0 - a1 / r) / r
    else:
        inverse = basic_sum(J_MAX, J_MAX, J_MAX / r, math.inf, alpha) / (float(sz(0.0, math.inf, alpha)) ** 2 * J_MAX)
    return 1.0 / inverse


def lag1_alpha(phase: np.ndarray, m: int) -> np.ndarray | None:
    """The power-law exponent alpha of the noise at factor m (Riley's lag-1 autocorrelation of the phase) of
    each column of phase (N,) or (N, K), or None when the phase decimated by m has fewer than MIN_POINTS
    points. Not limited to the model's three types."""
    x = np.asarray(phase, dtype=float)[::m]
    if len(x) < MIN_POINTS:
        return None
    x = x.reshape(len(x), -1)
    k = np.arange(len(x), dtype=float)
    x = x - np.polynomial.polynomial.polyval(k, np.polynomial.polynomial.polyfit(k, x, 2)).T
    alpha = np.zeros(x.shape[1], dtype=int)
    pending = np.ones(x.shape[1], dtype=bool)
    for d in range(_D + 1):
        centred = x - x.mean(axis=0)
        denominator = np.sum(centred * centred, axis=0)
        r1 = np.sum(centred[:-1] * centred[1:], axis=0) / np.where(denominator > 0.0, denominator, np.inf)
        rho = r1 / (1.0 + r1)
        done = pending & ((rho < 0.25) | (d == _D))
        alpha[done] = np.rint(-2.0 * rho[done]).astype(int) - 2 * d + 2
        pending &= ~done
        x = np.diff(x, axis=0)
    return alpha if np.ndim(phase) > 1 else alpha[0]


def model_alpha(alpha: int) -> int:
    """The model's nearest noise type: phase noises (alpha > 0, such as quantisation) count as white rate,
    whose EDF is the smaller (the interval the wider); steeper than random walk as random walk."""
    return min(max(alpha, ALPHAS[-1]), ALPHAS[0])
