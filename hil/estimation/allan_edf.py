"""EDF of the overlapping Allan variance by Greenhall's general algorithm, for the five power-law noises.

C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite differences", 35th
PTTI (2003), for the second difference (d = 2), the overlapping estimator (stride S = m) of the unmodified
variance (filter factor F = m), as Stable32 computes it. alpha is the exponent of the rate's ("frequency")
spectrum: 2 white PM (an IMU's output quantization), 1 flicker PM, 0 white rate, -1 flicker rate (bias
instability), -2 rate random walk. Time t is in units of tau.

    sw(t): -|t| (alpha 2), t^2 ln|t| (1), |t|^3 (0), -t^4 ln|t| (-1), -|t|^5 (-2)           (Eq. 7)
    sx(t) = F^2 [2 sw(t) - sw(t - 1/F) - sw(t + 1/F)], sw(t; alpha + 2) for F = infinity    (Eq. 8)
    sz(t) = 6 sx(t) - 4 sx(t - 1) - 4 sx(t + 1) + sx(t - 2) + sx(t + 2)                       (Eq. 9)
    BasicSum(J, M, S) = sz(0)^2 + (1 - J/M) sz(J/S)^2 + 2 sum_{j=1}^{J-1} (1 - j/M) sz(j/S)^2  (Eq. 10)

sz(t) is (proportional to) the covariance of two second differences t tau apart, so 1 / EDF = BasicSum /
(M sz(0)^2) with the sum cut at J = min(M, 3S), past which the differences share no sample. With N phase
points, M = N - 2m differences and r = M / m; J_max = 100. The paper's cases for F = m:

- alpha <= 0: J <= J_max: the sum with F = m where 3m <= J_max, else F = infinity; r > 3: (a0 - a1 / r) / r
  (Table 2); else the sum BasicSum(J_max, J_max, J_max / r) with F = infinity.
- alpha = 1: J <= J_max: the sum with F = m; else sz(0) is b0 + b1 ln m (Table 3) and 1 / EDF is
  (a0 - a1 / r) / r or the J_max sum with F = J_max / r, over (b0 + b1 ln m)^2 (Table 2).
- alpha = 2: exact, white phase samples: 1 / EDF = (1 + 2 sum_{1 <= k < r, k <= 2} (1 - k / r) rho_k^2) / M
  with rho_1 = -2/3, rho_2 = 1/6 the correlations of second differences m and 2m samples apart (for r > 2
  this is Table 2's (35/18 - 1 / r) / M).
"""

from __future__ import annotations

import math

import numpy as np

J_MAX = 100
ALPHAS = (2, 1, 0, -1, -2)  # white PM, flicker PM, white rate, bias instability (flicker rate), random walk
_D = 2
# Greenhall and Riley Table 2, d = 2: (a0, a1) per alpha of the unmodified variances; Table 3: (b0, b1)
_TABLE2 = {1: (790.0, 410.0), 0: (2.0 / 3.0, 1.0 / 3.0), -1: (0.852, 0.375), -2: (1.079, 0.368)}
_TABLE3 = (15.23, 12.0)
_WHITE_PM_RHO = (-2.0 / 3.0, 1.0 / 6.0)


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


def _summed(j_cut: int, m_count: float, stride: float, f: float, alpha: int, sz0: float | None = None) -> float:
    """1 / EDF from the basic sum: BasicSum / (M sz(0)^2), sz(0) the sum's own unless given."""
    sz0 = float(sz(0.0, f, alpha)) if sz0 is None else sz0
    return basic_sum(j_cut, m_count, stride, f, alpha) / (sz0 * sz0 * m_count)


def _white_pm_inverse(m_count: int, r: float) -> float:
    """1 / EDF of white PM, exact: second differences k m samples apart correlate as rho_k for k <= 2."""
    lags = [(k, rho) for k, rho in enumerate(_WHITE_PM_RHO, start=1) if k < r]
    return (1.0 + 2.0 * sum((1.0 - k / r) * rho * rho for k, rho in lags)) / m_count


def greenhall_edf(alpha: int, m: int, n_phase: int) -> float:
    """EDF of the overlapping Allan variance at factor m from n_phase phase points, noise exponent alpha."""
    m_count = n_phase - 2 * m  # M: second differences (Eq. 11 with L = 2m + 1, S = F = m)
    if m_count < 1:
        raise ValueError(f"factor {m} leaves no second difference in {n_phase} phase points")
    if alpha not in ALPHAS:
        raise ValueError(f"noise exponent alpha = {alpha} is outside 2..-2")
    j_cut, r = min(m_count, (_D + 1) * m), m_count / m
    if alpha == 2:
        return 1.0 / _white_pm_inverse(m_count, r)
    if alpha == 1:
        if j_cut <= J_MAX:
            return 1.0 / _summed(j_cut, m_count, m, m, alpha)
        b0, b1 = _TABLE3
        sz0 = b0 + b1 * math.log(m)
        if r > _D + 1:
            a0, a1 = _TABLE2[alpha]
            return sz0 * sz0 * r / (a0 - a1 / r)
        return 1.0 / _summed(J_MAX, J_MAX, J_MAX / r, J_MAX / r, alpha, sz0)
    if j_cut <= J_MAX:
        return 1.0 / _summed(j_cut, m_count, m, m if (_D + 1) * m <= J_MAX else math.inf, alpha)
    if r > _D + 1:
        a0, a1 = _TABLE2[alpha]
        return r / (a0 - a1 / r)
    return 1.0 / _summed(J_MAX, J_MAX, J_MAX / r, math.inf, alpha)
