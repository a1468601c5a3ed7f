"""The power-law noise type at each tau, identified as Stable32 identifies it (NIST SP 1065 section 5.6).

The rates (increments over T: the "frequency data") are averaged over non-overlapping groups of m, n of
them. Then, at each factor m of the grid, in order:

- n >= 30: the lag-1 autocorrelation method (W. J. Riley and C. A. Greenhall, "Power law noise
  identification using the lag 1 autocorrelation", EFTF 2004): r1 the lag-1 autocorrelation of the
  averages (their mean removed), delta = r1 / (1 + r1); while delta >= 0.25 and d < 2 the averages are
  differenced (d + 1); then alpha = -round(2 delta) - 2 d.
- 8 <= n < 30: the B1 ratio, the sample variance of the averages over their Allan variance (from the same
  averages), against its expected value for each noise (Barnes; Howe), B1(N, mu) = N (1 - N^mu) /
  (2 (N - 1) (1 - 2^mu)), N ln N / (2 (N - 1) ln 2) at mu = 0, with N the record's rate samples (as
  Stable32 takes it); the boundaries the geometric means of neighbouring expected values. mu = -2 (white
  or flicker PM) is split by R(n), the modified over the overlapping Allan variance at m, against the
  geometric mean of white PM's 1 / m and flicker PM's 3 ln(256/27) / (2 (1.038 + 3 ln(pi m))).
- n < 8: the noise type of the previous tau of the grid.

alpha is kept to 2..-2. These rules reproduce Stable32's noise type at every tau of its published runs on
NIST's 1000-point data set, an OCXO, a GPS receiver and a caesium clock (tests/test_allan_stable32.py).
"""

from __future__ import annotations

import math

import numpy as np

LAG1_POINTS = 30  # averages the lag-1 method needs
B1_POINTS = 8  # averages the B1 ratio needs; fewer keep the previous tau's type
_D_MAX = 2
_MU_ALPHA = ((-2, 2), (-1, 0), (0, -1), (1, -2))  # B1's tau exponent mu of the Allan variance, per alpha


def averages(sums: np.ndarray, counts: np.ndarray, m: int) -> np.ndarray:
    """Means of non-overlapping groups of m rows (n // m, K) from the running sums of the rates (missing rows
    taken as 0) and of the rows present, both (n + 1, K) from 0: a group's missing rows left out of its mean,
    a group with none present NaN. Each tau costs n / m operations, not n."""
    edges = np.arange(0, (len(sums) - 1) // m * m + 1, m)
    total, present = np.diff(sums[edges], axis=0), np.diff(counts[edges], axis=0)
    return np.where(present > 0, total / np.maximum(present, 1), np.nan)


def lag1_alpha(averaged: np.ndarray) -> int:
    """alpha of one column of averaged rates by the lag-1 autocorrelation method."""
    z, d = averaged[np.isfinite(averaged)], 0
    while True:
        centred = z - z.mean()
        denominator = float(np.sum(centred * centred))
        r1 = float(np.sum(centred[:-1] * centred[1:])) / denominator if denominator > 0.0 else 0.0
        delta = r1 / (1.0 + r1)
        if delta < 0.25 or d == _D_MAX:
            return _clipped(-round(2.0 * delta) - 2 * d)
        z, d = np.diff(z), d + 1


def b1_expected(n: int, mu: int) -> float:
    """Expected B1 ratio of n samples for the Allan variance's tau exponent mu."""
    if mu == 0:
        return n * math.log(n) / (2.0 * (n - 1) * math.log(2.0))
    return n * (1.0 - n**mu) / (2.0 * (n - 1) * (1.0 - 2.0**mu))


def b1_mu(averaged: np.ndarray, n_samples: int) -> int:
    """mu of one column of averaged rates by its B1 ratio against the expected values for n_samples."""
    z = averaged[np.isfinite(averaged)]
    allan = 0.5 * float(np.mean(np.diff(z) ** 2))
    ratio = float(np.var(z, ddof=1)) / allan if allan > 0.0 else 1.0
    expected = [b1_expected(n_samples, mu) for mu, _ in _MU_ALPHA]
    for (mu, _), low, high in zip(_MU_ALPHA, expected, expected[1:]):
        if ratio < math.sqrt(low * high):
            return mu
    return _MU_ALPHA[-1][0]


def rn_alpha(phase: np.ndarray, m: int) -> int:
    """White (2) or flicker (1) PM of one column of phase by R(n) = modified / overlapping Allan variance; white
    where fewer than m second differences leave no modified variance (a listed grid's first tau)."""
    second = phase[2 * m :] - 2.0 * phase[m:-m] + phase[: -2 * m]
    allan = float(np.mean(second * second))
    if len(second) < m or not allan > 0.0:
        return 2
    sums = np.concatenate([[0.0], np.cumsum(second)])
    modified = float(np.mean((sums[m:] - sums[:-m]) ** 2)) / (m * m)
    white, flicker = 1.0 / m, 3.0 * math.log(256.0 / 27.0) / (2.0 * (1.038 + 3.0 * math.log(math.pi * m)))
    return 2 if modified / allan < math.sqrt(white * flicker) else 1


def identify(rates: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """alpha (M, K) at each factor of the grid (ascending) and column of rates (n, K); NaN rows are missing."""
    y = np.asarray(rates, dtype=float)
    y = y[:, None] if y.ndim == 1 else y
    present = ~np.isnan(y)
    start = np.zeros((1, y.shape[1]))
    # the mean taken out (no type depends on it) keeps the running sums small; a missing rate counts as the mean
    phase = np.vstack([start, np.cumsum(np.where(present, y - np.nanmean(y, axis=0), 0.0), axis=0)])
    counts = np.vstack([start, np.cumsum(present, axis=0)])
    out = np.zeros((len(factors), y.shape[1]), dtype=int)
    for j, m in enumerate(int(f) for f in factors):
        averaged = averages(phase, counts, m)
        for k in range(y.shape[1]):
            if len(averaged) >= LAG1_POINTS:
                out[j, k] = lag1_alpha(averaged[:, k])
            elif len(averaged) >= B1_POINTS or j == 0:
                mu = b1_mu(averaged[:, k], len(y))
                out[j, k] = rn_alpha(phase[:, k], m) if mu == -2 else dict(_MU_ALPHA)[mu]
            else:
                out[j, k] = out[j - 1, k]
    return out


def _clipped(alpha: int) -> int:
    """alpha kept to the five types 2..-2."""
    return min(max(alpha, -2), 2)
