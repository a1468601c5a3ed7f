"""When an emulated device latches, what its counter says, and what its own clock reads.

A synchronised device counts the shared sync pulses, pulse p at t = p / rate, and ticks on every n-th
of them (``counts_per_tick``; n = 1 but for a table under a faster IMU): tick k at t = n k / rate,
with counter n k. A free-running one ticks on its own clock, which runs fast by ``clock_drift_ppm``
(delta = ppm * 1e-6): tick k of its period T = n / rate falls at true time k T / (1 + delta), and it
counts its ticks. Either way it latches ``latch_delay`` after its tick, plus a Gaussian jitter of
``latch_jitter_us`` (1 sigma), and its clock reads t (1 + delta) at true time t.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.config import DeviceTiming
from hil.units import PPM


@dataclass(frozen=True)
class DeviceClock:
    """Tick and latch instants (trial time, s) of one device, and its own time."""

    rate_hz: float  # counts per second of its counter: the pulse train's rate when synchronised
    latch_delay: float  # s
    timing: DeviceTiming
    counts_per_tick: int = 1  # steps of the counter from one tick to the next

    @property
    def drift(self) -> float:
        return self.timing.clock_drift_ppm * PPM

    @property
    def period(self) -> float:
        """True time between ticks."""
        rate = self.rate_hz * (1.0 + self.drift) if self.timing.free_running else self.rate_hz
        return self.counts_per_tick / rate

    def ticks(self, duration: float) -> int:
        """Ticks within a trial of ``duration`` s (the last one at or before its end)."""
        return int(np.floor(duration / self.period + 1e-9))

    def counters(self, k: np.ndarray) -> np.ndarray:
        """The device's counter at ticks k."""
        return np.asarray(k) * self.counts_per_tick

    def tick_times(self, k: np.ndarray) -> np.ndarray:
        return np.asarray(k, dtype=float) * self.period

    def latch_times(self, k: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Latch instants of ticks k; draws one jitter value per tick from ``rng`` when jitter is on."""
        t = self.tick_times(k) + self.latch_delay
        sigma = self.timing.latch_jitter_us * 1e-6
        return t + sigma * rng.standard_normal(len(t)) if sigma > 0 else t

    def device_time(self, t: np.ndarray) -> np.ndarray:
        """The device clock's reading at true times t."""
        return np.asarray(t, dtype=float) * (1.0 + self.drift)
