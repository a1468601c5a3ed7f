"""Deterministic parts taken out of a record before its Allan variance: ``--detrend none|linear|temperature``.

``linear``: the least-squares line of each column's rate against time, r_k = dx_k / T at the middle of its
interval, t_k = (k + 1/2) T (k counting the samples missing in gaps, whose NaN rows are left out of the fit
and stay NaN). Its slope is removed from the increments, dx_k - b (t_k - mean t) T: the rate ramp (IEEE 952's
R, signed), which the Allan variance then no longer holds; the mean rate, which the second differences remove
anyway, is kept.

``temperature``: the least-squares polynomial of degree TEMPERATURE_DEGREE of each column's rate in the IMU's
reported temperature about its mean, r_k = c_0 + sum_j c_j (T_k - mean T)^j, over the samples with both; the
part sum_j c_j (T_k - mean T)^j is removed from the increments where the temperature is known.
"""

from __future__ import annotations

import numpy as np

DETRENDS = ("none", "linear", "temperature")
TEMPERATURE_DEGREE = 2


def linear_trend(increments: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """The increments (n, K) less their rate's linear trend, and its slope per column (K,), rate per s."""
    dx = np.asarray(increments, dtype=float)
    t = (np.arange(len(dx)) + 0.5) * period
    present = ~np.isnan(dx).any(axis=1)
    centred = t - t[present].mean()
    rates = dx[present] / period
    slope = centred[present] @ (rates - rates.mean(axis=0)) / np.sum(centred[present] ** 2)
    return dx - np.outer(centred, slope) * period, slope


def temperature_trend(increments: np.ndarray, period: float,
                      temperature_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The increments (n, K) less the part of their rate a polynomial of the temperature (n,) deg C explains, and
    its coefficients c_1 .. c_d (d, K), rate per deg C^j about the mean temperature."""
    dx = np.asarray(increments, dtype=float)
    temperature = np.asarray(temperature_c, dtype=float)
    known = np.isfinite(temperature)
    both = known & ~np.isnan(dx).any(axis=1)
    powers = np.vander(temperature - temperature[both].mean(), TEMPERATURE_DEGREE + 1, increasing=True)
    coefficients = np.linalg.lstsq(powers[both], dx[both] / period, rcond=None)[0]
    explained = np.where(known[:, None], powers[:, 1:] @ coefficients[1:], 0.0)
    return dx - explained * period, coefficients[1:]
