"""Deterministic parts taken out of a record before its Allan variance: ``--detrend none|linear``.

``linear``: the least-squares line of each column's rate against time, r_k = dx_k / T at the middle of its
interval, t_k = (k + 1/2) T (k counting the samples missing in gaps, whose NaN rows are left out of the fit
and stay NaN). Its slope is removed from the increments, dx_k - b (t_k - mean t) T: the rate ramp (IEEE 952's
R, signed), which the Allan variance then no longer holds; the mean rate, which the second differences remove
anyway, is kept.
"""

from __future__ import annotations

import numpy as np

DETRENDS = ("none", "linear")


def linear_trend(increments: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """The increments (n, K) less their rate's linear trend, and its slope per column (K,), rate per s."""
    dx = np.asarray(increments, dtype=float)
    t = (np.arange(len(dx)) + 0.5) * period
    present = ~np.isnan(dx).any(axis=1)
    centred = t - t[present].mean()
    rates = dx[present] / period
    slope = centred[present] @ (rates - rates.mean(axis=0)) / np.sum(centred[present] ** 2)
    return dx - np.outer(centred, slope) * period, slope
