"""The tau grids of an Allan analysis, as averaging factors m (tau = m T, T the sample period).

``octave``: m = 1, 2, 4, ...; ``decade``: tau = 1, 2, 5 x 10^k s from the sample period up (Stable32's
decade run in seconds, the taus datasheets quote), each the nearest multiple of T; ``all``: every m the
record allows, whose overlapping variances cost n^2 / 2 operations for n samples (a CPU-minute for a triad
of 1e5 samples, days for the 2.9e6 of 8 h at 100 Hz); a list of taus in seconds, each a multiple of T. Every grid stops
where one second difference is left (2m <= n).
"""

from __future__ import annotations

import math

import numpy as np

GRIDS = ("octave", "decade", "all")
_MULTIPLE_TOLERANCE = 1e-6  # relative: a listed tau farther than this from m T is refused


def octave_factors(n_samples: int) -> np.ndarray:
    """Averaging factors m = 1, 2, 4, ... with at least one second difference (2m <= n_samples)."""
    return 2 ** np.arange(max(int(n_samples).bit_length() - 1, 0))


def decade_factors(n_samples: int, period: float) -> np.ndarray:
    """m of tau = 1, 2, 5 x 10^k s from the first such tau >= period, rounded to the nearest multiple of T."""
    decades = range(math.floor(math.log10(period)), math.ceil(math.log10(n_samples * period / 2.0)) + 1)
    taus = [mantissa * 10.0**k for k in decades for mantissa in (1.0, 2.0, 5.0)]
    factors = {round(tau / period) for tau in taus if tau >= period * (1.0 - _MULTIPLE_TOLERANCE)}
    return np.array(sorted(m for m in factors if 1 <= m and 2 * m <= n_samples), dtype=int)


def listed_factors(taus: tuple[float, ...], n_samples: int, period: float) -> np.ndarray:
    """m of each listed tau (s), which must be a multiple of the period and at most half the record."""
    out = []
    for tau in taus:
        m = round(tau / period)
        if m < 1 or abs(m * period - tau) > _MULTIPLE_TOLERANCE * tau:
            raise ValueError(f"tau {tau:g} s is not a multiple of the sample period {period:g} s")
        if 2 * m > n_samples:
            raise ValueError(f"tau {tau:g} s is longer than half the record ({n_samples * period / 2.0:g} s)")
        out.append(m)
    return np.array(sorted(set(out)), dtype=int)


def parse_taus(text: str) -> str | tuple[float, ...]:
    """``octave``, ``decade``, ``all`` or a comma-separated list of positive taus in seconds."""
    if text in GRIDS:
        return text
    try:
        taus = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise ValueError(f"--taus {text!r}: expected octave, decade, all or taus in s such as 1,10,100") from None
    if not all(math.isfinite(t) and t > 0.0 for t in taus):
        raise ValueError(f"--taus {text!r}: every tau must be a positive number of seconds")
    return taus


def tau_factors(grid: str | tuple[float, ...], n_samples: int, period: float) -> np.ndarray:
    """The averaging factors of ``grid`` (a name of GRIDS or taus in s) for n_samples at ``period``."""
    if grid == "octave":
        return octave_factors(n_samples)
    if grid == "decade":
        return decade_factors(n_samples, period)
    if grid == "all":
        return np.arange(1, n_samples // 2 + 1)
    if isinstance(grid, str):
        raise ValueError(f"unknown tau grid {grid!r}: expected one of {GRIDS} or taus in s")
    return listed_factors(tuple(grid), n_samples, period)
