"""The specific-force outlier gate: a sample far from the median of the samples before it is left out.

Sample j of a series is judged against the ``window`` samples before it: on every axis
``|f_j - median| <= max(sigmas * 1.4826 * MAD, floor)`` (MAD the median absolute deviation from that
median) or it is rejected. The medians are only needed where the answer is in doubt: the median lies
between the window's smallest and largest value and the limit is never below ``floor``, so a sample
within ``floor`` of both (in floating point, ``fl(f - min) <= floor`` and ``fl(max - f) <= floor``,
which bounds ``fl(|f - median|)`` because rounding is monotone) is accepted without them. The sliding
minimum and maximum cost O(n log window); the exact medians are formed for the remaining samples
alone (those near an outlier, or all of them when the noise is as large as the floor), by the same
operations as on the whole series, so the decisions are those of the full sliding median.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

MAD_TO_SIGMA = 1.4826  # robust sigma of a normal distribution from its median absolute deviation


def sliding_extreme(reduce: Callable[..., np.ndarray], x: np.ndarray, window: int) -> np.ndarray:
    """``reduce`` (np.minimum or np.maximum) over ``x[j : j + window]`` for every j, along axis 0.

    Extremes over power-of-two spans by doubling, then combined along the window's binary digits.
    """
    n_out = len(x) - window + 1
    out = None
    span, power, offset = 1, x, 0
    remaining = window
    while remaining:
        if remaining & 1:
            part = power[offset : offset + n_out]
            out = part if out is None else reduce(out, part)
            offset += span
        remaining >>= 1
        if remaining:
            power = reduce(power[:-span], power[span:])
            span *= 2
    return out


def accepted(series: np.ndarray, window: int, sigmas: float, floor: float) -> np.ndarray:
    """For ``series`` (window + M, 3): True for each of the last M rows that passes the gate against
    the ``window`` rows before it, (M,)."""
    values = series[window:]
    low = sliding_extreme(np.minimum, series[:-1], window)
    high = sliding_extreme(np.maximum, series[:-1], window)
    accept = np.all((values - low <= floor) & (high - values <= floor), axis=1)
    doubt = np.flatnonzero(~accept)
    if len(doubt):
        windows = sliding_window_view(series[:-1], window, axis=0)[doubt]  # (D, 3, window)
        centre = np.median(windows, axis=-1)
        spread = MAD_TO_SIGMA * np.median(np.abs(windows - centre[..., None]), axis=-1)
        limit = np.maximum(sigmas * spread, floor)
        accept[doubt] = np.all(np.abs(values[doubt] - centre) <= limit, axis=1)
    return accept
