"""How fresh a live trial's estimate is: the latency and age of each estimator update, in constant memory."""

from __future__ import annotations

import time
from collections import deque

from drivers.latency import LatencyHistogram

LATENCY_BINS = 100_000  # 10 us bins up to 1 s; the maximum is kept exactly


class LatencyStats:
    """How fresh the estimate is (ms), in constant memory however long the trial:

    - ``latency``: from the arrival of the chunk that completed a block of samples to the estimator
      having taken the block;
    - ``age``: from the arrival of the chunk that completed the oldest sample the estimator took then
      (a sample left over from a block waits for the next one, and its age counts from its own chunk).
    """

    def __init__(self) -> None:
        self.latency = LatencyHistogram(bins=LATENCY_BINS)
        self.age = LatencyHistogram(bins=LATENCY_BINS)
        self._arrivals: deque[tuple[float, int]] = deque()  # (chunk arrival, samples aligned once it was fed)
        self._taken = 0  # samples aligned before the estimator's last update
        self._last = (0.0, 0)  # (arrival, samples aligned) of the chunk fed last

    def fed(self, arrival: float, aligned: int) -> None:
        """A chunk that arrived at ``arrival`` has been fed; ``aligned`` samples are now aligned in all. Only
        chunks that completed samples are kept, and only until the estimator has taken those."""
        self._last = (arrival, aligned)
        if aligned > (self._arrivals[-1][1] if self._arrivals else self._taken):
            self._arrivals.append((arrival, aligned))

    def updated(self, waiting: int) -> None:
        """The estimator took every aligned sample but ``waiting`` with the chunk fed last."""
        now = time.time()
        arrival, aligned = self._last
        oldest = next((t for t, done in self._arrivals if done > self._taken), arrival)
        self.latency.add(now - arrival)
        self.age.add(now - oldest)
        self._taken = aligned - waiting
        while self._arrivals and self._arrivals[0][1] <= self._taken:
            self._arrivals.popleft()

    def percentiles_ms(self) -> dict[str, float]:
        if not self.latency.count:
            return {}
        out = {}
        for name, values in (("latency", self.latency), ("age", self.age)):
            p50, p99 = values.percentiles_ms([50, 99])
            out.update({f"{name}_p50_ms": p50, f"{name}_p99_ms": p99, f"{name}_max_ms": values.max_ms()})
        return out
