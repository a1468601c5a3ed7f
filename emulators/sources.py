"""Emulated devices' frames: what each device sends at each tick of its clock.

Each device ticks on its :class:`emulators.clocks.DeviceClock` (the shared sync pulses, or its own
clock when free-running); tick k of the IMU reports the increments over its latch interval, tick k of
the table the gimbal angles at its latch instant; both carry their clock's counter (its start plus k,
or plus n k for a table latching every n-th pulse; from 0 again after a power cycle, whose ticks are
not sent; an IMU fed by the emulated supply is silent while its output is off, and boots when it comes back
on, with a new turn-on bias). Frames are encoded by the drivers' codecs, so the emulator speaks
exactly what the drivers read. The table's motion is the servo's (:mod:`emulators.servo`): a
:class:`DeviceStream` computes its frames a chunk ahead and recomputes the chunk when the servo's
plan (or the supply's output) changes, from a snapshot of its random state, so a command changes the frames
from the next pulse and everything stays reproducible. :mod:`emulators.paced_writer` puts the frames on the ports.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from drivers.tts1 import FULL_TURN_UDEG, UDEG_PER_RAD, Status, Tts1Codec
from emulators.clocks import TURN_ON_STREAM, DeviceClock, turn_on_offset_ug
from emulators.faults import flagged_samples
from emulators.sensor_errors import SensorErrorModel
from emulators.servo import Servo
from emulators.truth import Truth
from hil.config_emulated import ImuFaultConfig
from hil.samples import ImuSample, TableSample
from hil.units import UG


@dataclass(frozen=True)
class Emission:
    """One device frame: the pulse it ticks on, the trial time it is written, the latest instant it depends
    on, whether the device is powered to send it, and whether it flags its sample invalid."""

    tick: int
    t: float
    latest: float
    payload: Any
    powered: bool = True
    invalid: bool = False


class FrameSource:
    """Computes one device's frames for a run of ticks; its random state is copied to replay a chunk."""

    def __init__(self, clock: DeviceClock, seed: int, device: int) -> None:
        self.clock = clock
        self.state: dict[str, Any] = {"rng": np.random.Generator(np.random.PCG64(np.random.SeedSequence(
            [seed, device, 1]))), "last": clock.latch_delay}  # "last": end of the previous interval

    def compute(self, k: np.ndarray, truth: Truth, servo: Servo) -> list[Emission]:
        raise NotImplementedError


class ImuSource(FrameSource):
    """IMU frames: increments over each latch interval, with the sensor errors, encoded by ``codec``; the status
    word healthy but where the ``faults`` flag a sample (the codec's start-up flags raised) and where a gyro reads
    its range (``imu.errors.gyro_range_dps``: the codec's clip flag of that axis raised); the sensor's
    temperature where the frames carry one. Each power-on by the emulated supply adds a turn-on bias to the
    accelerometers' (1-sigma ``turn_on_bias_ug`` per axis, ug)."""

    def __init__(self, clock: DeviceClock, seed: int, codec: Any, errors: SensorErrorModel,
                 faults: ImuFaultConfig | None = None, turn_on_bias_ug: tuple[float, ...] = (0.0, 0.0, 0.0)) -> None:
        super().__init__(clock, seed, 0)
        self.codec, self.seed, self.turn_on_bias_ug = codec, seed, turn_on_bias_ug
        self.faults = faults or ImuFaultConfig()
        self.state["errors"] = errors
        self.state["flags_rng"] = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, 0, 2])))

    def compute(self, k: np.ndarray, truth: Truth, servo: Servo) -> list[Emission]:
        s, codec, clock = self.state, self.codec, self.clock
        latch = clock.latch_times(k, s["rng"])
        warm = latch - clock.powered_at(k)  # the self-heating's time since power-on
        dtheta, dv = truth.increments(s["last"], latch)
        dtheta, dv = s["errors"].apply(latch, dtheta, dv, self.turn_on_bias(k), warm)
        s["last"] = float(latch[-1])
        dev = clock.device_time(latch).tolist() if codec.device_time else [None] * len(k)
        flagged = flagged_samples(self.faults, latch, clock.since_power_on(k), s["flags_rng"])
        clipped = s["errors"].gyro_clipped()
        raised = [(codec.start_up_flags if bad else ()) + tuple(self.clip_flags(axes)) for bad, axes in
                  zip(flagged.tolist(), np.zeros((len(k), 3), bool) if clipped is None else clipped)]
        temperature = s["errors"].temperature_c(latch, warm).tolist()
        return [Emission(int(i), float(t), float(end), codec.encode(codec.from_sample(
                    ImuSample(int(c), tuple(a), tuple(b), device_time=d, status=codec.flagged_status(names),
                              temperature_c=temp))), bool(on), bool(names))
                for i, c, t, end, a, b, d, on, names, temp in zip(
                    clock.pulses(k), clock.counters(k), clock.tick_times(k), latch, dtheta.tolist(), dv.tolist(), dev,
                    clock.powered(k), raised, temperature)]

    def clip_flags(self, axes: np.ndarray) -> list[str]:
        """The codec's clip flags of the gyro ``axes`` (3,) that read their range (none for a codec without)."""
        return [name for name, hit in zip(self.codec.clip_flags, axes.tolist()) if hit]

    def turn_on_bias(self, k: np.ndarray) -> np.ndarray | None:
        """The turn-on bias (m/s^2, N x 3) at ticks k, of the supply's power-on they follow (None: no power-on)."""
        supply = self.clock.supply
        if supply is None or not supply.switches:
            return None
        _, number = supply.boots(k)
        drawn = {n: turn_on_offset_ug(self.turn_on_bias_ug, (self.seed, TURN_ON_STREAM, n)) * UG
                 for n in set(number.tolist()) if n}
        return np.array([drawn.get(n, np.zeros(3)) for n in number.tolist()]).reshape(len(number), 3)


class TableSource(FrameSource):
    """``tts1`` frames: the encoder angles and the servo's status at each latch instant, the clock's counter
    as their sync counter.

    ``zero_offset`` (outer, middle, inner) rad is ``turntable.zero_offset_arcsec``, the true gimbal angle
    minus the encoder reading: the frames report ``true - zero_offset``.
    """

    def __init__(self, clock: DeviceClock, seed: int, zero_offset: np.ndarray | None = None) -> None:
        super().__init__(clock, seed, 1)
        self.codec = Tts1Codec()
        self.flags = int(Status.FREE_RUNNING) if clock.timing.free_running else 0
        self.zero_offset = np.zeros(3) if zero_offset is None else np.asarray(zero_offset, dtype=float)

    def compute(self, k: np.ndarray, truth: Truth, servo: Servo) -> list[Emission]:
        latch = self.clock.latch_times(k, self.state["rng"])
        angles = truth.angles(latch) - self.zero_offset
        status = servo.motion.status(latch, servo.limits) | self.flags
        clock, codec = self.clock, self.codec
        return [Emission(int(p), float(t), float(end), codec.encode(codec.from_sample(
                    TableSample(int(c), tuple(a), latch_delay=clock.latch_delay, status=int(st)))), bool(on))
                for p, c, t, end, a, st, on in zip(clock.pulses(k), clock.counters(k), clock.tick_times(k), latch,
                                                   angles.tolist(), status, clock.powered(k))]


def encoder_reading(true_angles: np.ndarray, zero_offset: np.ndarray) -> np.ndarray:
    """The angles (N, 3) rad that :class:`TableSource`'s frames decode to for true gimbal angles (N, 3) rad:
    the encoder reading ``true - zero_offset`` on the frame's 1e-6 deg grid, wrapped to [-180, 180) deg
    (:func:`drivers.tts1.wrap_udeg`, rounding half to even as it does)."""
    udeg = np.rint((np.asarray(true_angles, dtype=float) - zero_offset) * UDEG_PER_RAD)
    half = FULL_TURN_UDEG // 2
    return ((udeg + half) % FULL_TURN_UDEG - half) / UDEG_PER_RAD


class DeviceStream:
    """One device's emissions in tick order, computed ``chunk`` ticks ahead with the servo's current plan.

    Call :meth:`pop` with the servo's lock held (the supply switches under it too): a chunk computed under an
    older plan or supply revision is recomputed from its starting state, which leaves the frames before the
    change unchanged.
    """

    def __init__(self, source: FrameSource, truth: Truth, ticks: int, chunk: int) -> None:
        self.source, self.truth, self.ticks, self.chunk = source, truth, ticks, chunk
        self._start = 1  # first tick of the cached chunk
        self._snapshot = copy.deepcopy(source.state)
        self._cache: list[Emission] = []
        self._pos = 0
        self._revision: tuple[int, int] | None = None  # the servo's and the supply's revisions the chunk is of

    def done(self) -> bool:
        return self._start + self._pos > self.ticks

    def next_time(self) -> float:
        """Write time of the next tick (trial time)."""
        return (self._start + self._pos) * self.source.clock.period

    def pop(self, servo: Servo) -> Emission:
        if self._pos == len(self._cache):
            self._start += self._pos
            self._snapshot = copy.deepcopy(self.source.state)
            self._cache, self._pos = [], 0
        supply = self.source.clock.supply
        revision = (servo.revision, supply.revision if supply is not None else 0)
        if not self._cache or self._revision != revision:
            self.source.state = copy.deepcopy(self._snapshot)
            k = np.arange(self._start, min(self._start + self.chunk, self.ticks + 1))
            self._cache = self.source.compute(k, replace(self.truth, motion=servo.motion), servo)
            self._revision = revision
        self._pos += 1
        if supply is not None:
            supply.emitted = self._start + self._pos - 1
        return self._cache[self._pos - 1]
