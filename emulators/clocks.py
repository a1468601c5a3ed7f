"""When an emulated device latches, what its counter says, and what its own clock reads.

A synchronised device counts the shared sync pulses, pulse p at t = p / rate, and ticks on every n-th
of them (``counts_per_tick``; n = 1 but for a table under a faster IMU): tick k at t = n k / rate,
pulse n k. A free-running one ticks on its own clock, which runs fast by ``clock_drift_ppm``
(delta = ppm * 1e-6): tick k of its period T = n / rate falls at true time k T / (1 + delta), and it
counts its ticks. Either way it latches ``latch_delay`` after its tick, plus a Gaussian jitter of
``latch_jitter_us`` (1 sigma), and its clock reads t (1 + delta) at true time t.

Its counter at tick k is ``counter_start + n k``, each device counting from its own start
(:func:`counter_starts`). A power cycle (``faults.power_cycle_at_s``) silences the ticks inside its window;
the first tick after it carries counter 0, the next n, 2n ... A device fed by the emulated supply
(:class:`PowerLine`, ``environment.power``) is silent while the supply's output is off and boots when it comes
back on: as after a power cycle its first tick carries counter 0, the start-up flags and the warm-up run
from it, and it has a new turn-on bias (:func:`turn_on_offset_ug`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from drivers.registry import imu_codec
from hil.config import Config, DeviceTiming, FaultConfig
from hil.units import PPM

DRAW_RANGE = 1 << 20  # drawn table starts (and IMU ones without a counter modulus) lie below it: float times stay exact
COUNTER_STREAM = 2  # the draw's SeedSequence([seed, 2]), apart from the devices' own streams [seed, 0 | 1, ...]
TURN_ON_STREAM = 3  # the n-th power-on's turn-on bias: SeedSequence([seed, 3, n])


def turn_on_offset_ug(spread_ug: Sequence[float], key: Sequence[int]) -> np.ndarray:
    """A power-on's turn-on bias about the configured one (ug, 3): a normal draw of 1-sigma ``spread_ug`` per
    axis (``imu.errors.turn_on_bias_ug``), from the random stream ``key``."""
    return np.random.default_rng(list(key)).normal(size=3) * np.asarray(spread_ug, dtype=float)


class PowerLine:
    """The emulated supply's output feeding a device while it streams: powered from the start; each switch
    takes effect at the device's first tick after those already emitted (:attr:`emitted`). Not locked itself:
    switch it with the lock held that the pulse loop pops frames under (the servo's)."""

    def __init__(self) -> None:
        self.switches: list[tuple[int, bool, int]] = []  # (first tick, on, power-on number or 0), in order
        self.emitted = 0  # the last tick emitted
        self.revision = 0  # bumped by every switch: frames computed ahead are computed again

    @property
    def on(self) -> bool:
        return not self.switches or self.switches[-1][1]

    def switch(self, on: bool) -> None:
        """The output on or off from the next tick; switched on from off, the device boots (its n-th power-on)."""
        boots = sum(1 for *_, n in self.switches if n)
        self.switches.append((self.emitted + 1, on, boots + 1 if on and not self.on else 0))
        self.revision += 1

    def powered(self, k: np.ndarray) -> np.ndarray:
        """True for the ticks k at which the output is on."""
        k = np.asarray(k)
        state = np.ones(k.shape, dtype=bool)
        for tick, on, _ in self.switches:
            state[k >= tick] = on
        return state

    def boots(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tick of the last power-on at or before each tick k (-1: none since the start) and its number (0)."""
        k = np.asarray(k)
        tick, number = np.full(k.shape, -1), np.zeros(k.shape, dtype=int)
        for at, _, n in self.switches:
            if n:
                tick[k >= at], number[k >= at] = at, n
        return tick, number


@dataclass(frozen=True)
class DeviceClock:
    """Tick and latch instants (trial time, s) of one device, and its own time."""

    rate_hz: float  # counts per second of its counter: the pulse train's rate when synchronised
    latch_delay: float  # s
    timing: DeviceTiming
    counts_per_tick: int = 1  # steps of the counter from one tick to the next
    counter_start: int = 0  # the counter at tick 0
    power_cycle: tuple[float, float] | None = None  # (from, for) s of trial time: silent, then counting from 0
    supply: PowerLine | None = field(default=None, compare=False)  # the emulated supply's output feeding it

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
        """True for the ticks k the device sends (False inside the power cycle or with the supply off)."""
        k = np.asarray(k)
        on = np.ones(k.shape, dtype=bool) if self.supply is None else self.supply.powered(k)
        if self.power_cycle is None:
            return on
        first, end = self._off()
        return on & ((k < first) | (k >= end))

    def _boot(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tick each tick k counts from (0, a power cycle's end, the supply's last power-on) and the
        counter at that tick (``counter_start``, else 0: a booted device counts from zero)."""
        k = np.asarray(k)
        tick, counter = np.zeros(k.shape, dtype=int), np.full(k.shape, self.counter_start)
        if self.power_cycle is not None:
            _, end = self._off()
            tick, counter = np.where(k >= end, end, tick), np.where(k >= end, 0, counter)
        if self.supply is not None:
            boot, _ = self.supply.boots(k)
            later = boot > tick
            tick, counter = np.where(later, boot, tick), np.where(later, 0, counter)
        return tick, counter

    def counters(self, k: np.ndarray) -> np.ndarray:
        """The device's counter at ticks k."""
        tick, counter = self._boot(k)
        return counter + self.pulses(np.asarray(k) - tick)

    def since_power_on(self, k: np.ndarray) -> np.ndarray:
        """Seconds the device has been powered at ticks k: from the trial's start, a power cycle's end or the
        supply's last power-on."""
        tick, _ = self._boot(k)
        return self.tick_times(np.asarray(k) - tick)

    def powered_at(self, k: np.ndarray) -> np.ndarray:
        """The trial time of the last power-on at or before ticks k (0.0: the trial's start)."""
        return self.tick_times(self._boot(k)[0])

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
    """The IMU's and the table's clocks of a config; the IMU's fed by a :class:`PowerLine` when the config has
    an emulated supply (``environment.power.source: emulator``)."""
    imu, table = cfg.imu, cfg.turntable
    imu_start, table_start = counter_starts(cfg)
    power = cfg.environment.power
    supply = PowerLine() if power is not None and power.source == "emulator" else None
    return (DeviceClock(cfg.imu_rate_hz, imu.latch_delay_us * 1e-6, imu.timing, 1, imu_start,
                        _power_cycle(imu.faults), supply),
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
