"""When an emulated device latches, what its counter says, and what its own clock reads.

A synchronised device counts the shared sync pulses, pulse p at t = p / rate, and ticks on every n-th
of them (``counts_per_tick``; n = 1 but for a table under a faster IMU): tick k at t = n k / rate,
pulse n k. A free-running one ticks on its own clock, which runs fast by ``clock_drift_ppm``
(delta = ppm * 1e-6): tick k of its period T = n / rate falls at true time k T / (1 + delta), and it
counts its ticks. Either way it latches ``latch_delay`` after its tick, plus a Gaussian jitter of
``latch_jitter_us`` (1 sigma), and its clock reads t (1 + delta) at true time t.

Its counter at tick k is ``counter_start + n k``, each device counting from its own start
(:func:`counter_starts`). A power cycle silences the ticks inside its window; the first tick after
it carries counter 0, the next n, 2n ...
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.registry import imu_codec
from hil.config import Config, DeviceTiming, FaultConfig
from hil.units import PPM

DRAW_RANGE = 1 << 20  # drawn table starts (and IMU ones without a counter modulus) lie below it: float times stay exact
COUNTER_STREAM = 2  # the draw's SeedSequence([seed, 2]), apart from the devices' own streams [seed, 0 | 1, ...]


@dataclass(frozen=True)
class DeviceClock:
    """Tick and latch instants (trial time, s) of one device, and its own time."""

    rate_hz: float  # counts per second of its counter: the pulse train's rate when synchronised
    latch_delay: float  # s
    timing: DeviceTiming
    counts_per_tick: int = 1  # steps of the counter from one tick to the next
    counter_start: int = 0  # the counter at tick 0
    power_cycle: tuple[float, float] | None = None  # (from, for) s of trial time: silent, then counting from 0

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

    def pulses(self, k: np.ndarray) -> np.ndarray:
        """The pulse of the train (free-running: of its own clock) that ticks k fall on."""
        return np.asarray(k) * self.counts_per_tick

    def first_tick(self, t: float) -> int:
        """The first tick at or after trial time t."""
        return int(np.ceil(t / self.period - 1e-9))

    def _off(self) -> tuple[int, int]:
        """The first tick silenced by the power cycle and the first one after it (equal: no silence)."""
        start, length = self.power_cycle
        return self.first_tick(start), self.first_tick(start + length)

    def powered(self, k: np.ndarray) -> np.ndarray:
        """True for the ticks k the device sends (False inside the power cycle)."""
        k = np.asarray(k)
        if self.power_cycle is None:
            return np.ones(k.shape, dtype=bool)
        first, end = self._off()
        return (k < first) | (k >= end)

    def counters(self, k: np.ndarray) -> np.ndarray:
        """The device's counter at ticks k."""
        k = np.asarray(k)
        counts = self.counter_start + self.pulses(k)
        if self.power_cycle is None:
            return counts
        _, end = self._off()
        return np.where(k >= end, self.pulses(k - end), counts)

    def since_power_on(self, k: np.ndarray) -> np.ndarray:
        """Seconds the device has been powered at ticks k: from the trial's start, or from a power cycle's end."""
        k = np.asarray(k)
        if self.power_cycle is None:
            return self.tick_times(k)
        _, end = self._off()
        return self.tick_times(np.where(k >= end, k - end, k))

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


def _power_cycle(faults: FaultConfig) -> tuple[float, float] | None:
    return None if faults.power_cycle_at_s is None else (faults.power_cycle_at_s, faults.power_cycle_s)


def device_clocks(cfg: Config) -> tuple[DeviceClock, DeviceClock]:
    """The IMU's and the table's clocks of a config."""
    imu, table = cfg.imu, cfg.turntable
    imu_start, table_start = counter_starts(cfg)
    return (DeviceClock(cfg.imu_rate_hz, imu.latch_delay_us * 1e-6, imu.timing, 1, imu_start,
                        _power_cycle(imu.faults)),
            DeviceClock(cfg.table_counter_rate_hz, table.latch_delay_us * 1e-6, table.timing,
                        cfg.table_counts_per_frame, table_start, _power_cycle(table.faults)))


def imu_counter_modulus(cfg: Config) -> int:
    """How many values the IMU frames' counter takes (KVH 1750 128, Xsens 65536, CAN the DBC sync
    signal's); :data:`DRAW_RANGE` for frames without one."""
    codec = imu_codec(cfg.imu, cfg.imu_rate_hz)
    return codec.counter_modulus or DRAW_RANGE


def counter_starts(cfg: Config) -> tuple[int, int]:
    """The IMU's and the table's counter at trial time 0: ``timing.counter_start``, or when left out, drawn
    from ``trial.seed`` (the IMU's uniformly over its counter's values, the table's over [0, :data:`DRAW_RANGE`)
    and never equal to the IMU's): devices count from their own starts, as in a lab."""
    given = cfg.imu.timing.counter_start, cfg.turntable.timing.counter_start
    if None not in given:
        return given
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([cfg.trial.seed, COUNTER_STREAM])))
    imu = int(rng.integers(imu_counter_modulus(cfg)))
    table = int(rng.integers(DRAW_RANGE - 1))
    table += table >= imu  # uniform over the range without the IMU's value
    return (imu if given[0] is None else given[0]), (table if given[1] is None else given[1])
