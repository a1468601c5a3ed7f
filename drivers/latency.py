"""Latency statistics in constant memory: a histogram of fixed bins, however long the run.

Values are added in seconds and read back in milliseconds: percentiles at the resolution of a bin
(the upper edge of the bin the percentile falls in), the maximum exactly. A value beyond the last
bin is counted in the last bin (its percentile then reads as the histogram's range); a negative
value in the first.
"""

from __future__ import annotations

import numpy as np

BIN_S = 10e-6  # default resolution: 10 us
BINS = 10_000  # default range: up to 100 ms


class LatencyHistogram:
    """Latencies (s) counted in ``bins`` bins of ``bin_s``; percentiles and maximum in ms."""

    def __init__(self, bin_s: float = BIN_S, bins: int = BINS) -> None:
        if not bin_s > 0 or bins < 1:
            raise ValueError(f"latency histogram: bin_s must be positive and bins at least 1, got {bin_s}, {bins}")
        self.bin_s, self.bins = bin_s, bins
        self.counts = np.zeros(bins, dtype=np.int64)
        self.count = 0  # values added so far
        self._max: float | None = None
        self._top = 0  # the highest bin counted in: percentiles sum the bins up to it only

    def add(self, seconds: float) -> None:
        k = min(max(int(seconds / self.bin_s), 0), self.bins - 1)
        self.counts[k] += 1
        self.count += 1
        self._top = max(self._top, k)
        self._max = seconds if self._max is None else max(self._max, seconds)

    def percentile_ms(self, q: float) -> float | None:
        """The q-th percentile (0-100), ms rounded to the microsecond; None before the first value."""
        return self.percentiles_ms([q])[0]

    def percentiles_ms(self, qs: list[float]) -> list[float | None]:
        """:meth:`percentile_ms` of each of ``qs``, from one pass over the bins."""
        if self.count == 0:
            return [None] * len(qs)
        ks = np.searchsorted(np.cumsum(self.counts[: self._top + 1]), np.asarray(qs) / 100.0 * self.count)
        return [round((int(k) + 1) * self.bin_s * 1e3, 3) for k in ks]

    def max_ms(self) -> float | None:
        """The largest value added, ms; None before the first value."""
        return None if self._max is None else self._max * 1e3
