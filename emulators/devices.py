"""Emulated devices: frame sources on device clocks, and writers that put the frames on their ports
(:mod:`emulators.ports`: ptys or a CAN bus).

Each device ticks on its :class:`emulators.timing.DeviceClock` (the shared sync pulses, or its own
clock when free-running); tick k of the IMU reports the increments over its latch interval, tick k of
the table the gimbal angles at its latch instant; both carry their clock's counter (k, or n k for a
table latching every n-th pulse). Frames are encoded by
the drivers' codecs, so the emulator speaks exactly what the drivers read. The table's motion is the
servo's (:mod:`emulators.servo`): a :class:`DeviceStream` computes its frames a chunk ahead and
recomputes the chunk when the servo's plan changes, from a snapshot of its random state, so a command
changes the frames from the next pulse and everything stays reproducible.
"""

from __future__ import annotations

import copy
import queue
import threading
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from drivers.kvh1750 import STATUS_ALL_VALID
from drivers.tts1 import Status, Tts1Codec
from emulators.faults import FaultInjector
from emulators.ports import WAIT_S, wait_for_readers
from emulators.sensor_errors import SensorErrorModel
from emulators.servo import Servo
from emulators.timing import DeviceClock
from emulators.truth import Truth
from hil.samples import ImuSample, TableSample

DRAIN_S = 5.0  # longest wait for a reader to take the bytes queued before an unplug
REOPEN_SETTLE_S = 0.5  # after a replug, the longest wait for a reader to finish opening the port
LATENCY_BIN_S = 10e-6  # resolution of the write-latency histogram
LATENCY_BINS = 10_000  # up to 100 ms; later writes land in the last bin


@dataclass(frozen=True)
class Emission:
    """One device frame: its tick, the trial time it is written, the latest instant it depends on."""

    tick: int
    t: float
    latest: float
    payload: Any


class FrameSource:
    """Computes one device's frames for a run of ticks; its random state is copied to replay a chunk."""

    def __init__(self, clock: DeviceClock, seed: int, device: int) -> None:
        self.clock = clock
        self.state: dict[str, Any] = {"rng": np.random.Generator(np.random.PCG64(np.random.SeedSequence(
            [seed, device, 1]))), "last": clock.latch_delay}  # "last": end of the previous interval

    def compute(self, k: np.ndarray, truth: Truth, servo: Servo) -> list[Emission]:
        raise NotImplementedError


class ImuSource(FrameSource):
    """IMU frames: increments over each latch interval, with the sensor errors, encoded by ``codec``."""

    def __init__(self, clock: DeviceClock, seed: int, codec: Any, errors: SensorErrorModel,
                 device_time: bool) -> None:
        super().__init__(clock, seed, 0)
        self.codec, self.device_time = codec, device_time
        self.state["errors"] = errors
        self.status = STATUS_ALL_VALID if codec.name == "kvh1750" else 0

    def compute(self, k: np.ndarray, truth: Truth, servo: Servo) -> list[Emission]:
        s, codec = self.state, self.codec
        latch = self.clock.latch_times(k, s["rng"])
        dtheta, dv = truth.increments(s["last"], latch)
        dtheta, dv = s["errors"].apply(latch, dtheta, dv)
        s["last"] = float(latch[-1])
        dev = self.clock.device_time(latch).tolist() if self.device_time else [None] * len(k)
        ticks = self.clock.tick_times(k)
        return [Emission(int(i), float(t), float(end), codec.encode(codec.from_sample(
                    ImuSample(int(i), tuple(a), tuple(b), device_time=d, status=self.status))))
                for i, t, end, a, b, d in zip(k, ticks, latch, dtheta.tolist(), dv.tolist(), dev)]


class TableSource(FrameSource):
    """``tts1`` frames: the gimbal angles and the servo's status at each latch instant, the clock's counter
    as their sync counter and emission tick."""

    def __init__(self, clock: DeviceClock, seed: int) -> None:
        super().__init__(clock, seed, 1)
        self.codec = Tts1Codec()
        self.flags = int(Status.FREE_RUNNING) if clock.timing.free_running else 0

    def compute(self, k: np.ndarray, truth: Truth, servo: Servo) -> list[Emission]:
        latch = self.clock.latch_times(k, self.state["rng"])
        angles = truth.angles(latch)
        status = servo.motion.status(latch, servo.limits) | self.flags
        ticks, codec, delay = self.clock.tick_times(k), self.codec, self.clock.latch_delay
        return [Emission(int(c), float(t), float(end), codec.encode(codec.from_sample(
                    TableSample(int(c), tuple(a), latch_delay=delay, status=int(st)))))
                for c, t, end, a, st in zip(self.clock.counters(k), ticks, latch, angles.tolist(), status)]


class DeviceStream:
    """One device's emissions in tick order, computed ``chunk`` ticks ahead with the servo's current plan.

    Call :meth:`pop` with the servo's lock held: a chunk computed under an older plan revision is
    recomputed from its starting state, which leaves the frames before the change unchanged.
    """

    def __init__(self, source: FrameSource, truth: Truth, ticks: int, chunk: int) -> None:
        self.source, self.truth, self.ticks, self.chunk = source, truth, ticks, chunk
        self._start = 1  # first tick of the cached chunk
        self._snapshot = copy.deepcopy(source.state)
        self._cache: list[Emission] = []
        self._pos = 0
        self._revision = -1

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
        if not self._cache or self._revision != servo.revision:
            self.source.state = copy.deepcopy(self._snapshot)
            k = np.arange(self._start, min(self._start + self.chunk, self.ticks + 1))
            self._cache = self.source.compute(k, replace(self.truth, motion=servo.motion), servo)
            self._revision = servo.revision
        self._pos += 1
        return self._cache[self._pos - 1]


class LatencyHistogram:
    """Write latencies (s) in fixed bins: constant memory however long the run."""

    def __init__(self) -> None:
        self.counts = np.zeros(LATENCY_BINS, dtype=np.int64)

    def add(self, latency: float) -> None:
        self.counts[min(max(int(latency / LATENCY_BIN_S), 0), LATENCY_BINS - 1)] += 1

    def percentile_ms(self, q: float) -> float | None:
        total = int(self.counts.sum())
        if total == 0:
            return None
        k = int(np.searchsorted(np.cumsum(self.counts), q / 100.0 * total))
        return round((k + 1) * LATENCY_BIN_S * 1e3, 3)


class DeviceWriter:
    """Writes one device's emissions from its own thread: faults, unplug window, wire-time pacing.

    A frame of n bytes at ``baudrate`` (10 bits a byte) is written when its last byte would have
    arrived: ``wire = 10 n / baudrate`` after the line is free, divided by the speed. The latency
    from a frame's pulse to the end of its write goes into :attr:`latency`. Without ``wait_readers``
    the device behaves like powered hardware: a frame that no reader would take (nobody holds the
    port, or the reader's input queue is full) is lost, as on a UART, and counted in :attr:`lost_unread`.
    """

    def __init__(self, name: str, port: Any, faults: FaultInjector, baudrate: int | None, speed: float | None,
                 stop: threading.Event, wait_readers: bool) -> None:
        self.name, self.port, self.faults, self.baudrate, self.speed = name, port, faults, baudrate, speed
        self.stop, self.wait_readers = stop, wait_readers
        self.latency = LatencyHistogram()
        self.frames = 0
        self.lost_unread = 0
        self.queue: queue.Queue = queue.Queue(maxsize=0 if speed else 256)
        self._line_free = 0.0
        self.thread = threading.Thread(target=self._run, name=f"emulate-{name}", daemon=True)
        self.thread.start()

    def put(self, emission: Emission | None, due: float | None) -> bool:
        """Queue a frame due at monotonic time ``due`` (None: unpaced), or None to finish; False if stopped."""
        while not self.stop.is_set():
            try:
                self.queue.put((emission, due), timeout=WAIT_S)
                return True
            except queue.Full:
                continue
        return False

    def _run(self) -> None:
        while True:
            emission, due = self.queue.get()
            if emission is None:
                self._send(self.faults.flush(), due)
                return
            if not self._plugged(emission.t):
                continue
            if not self._send(self.faults.frames(emission.payload), due):
                return

    def _plugged(self, t: float) -> bool:
        """False while the device is unplugged at trial time t (the frame is lost)."""
        counts, port = self.faults.counts, self.port
        if self.faults.unplugged(t):
            if port.plugged:
                port.drain(self.stop, DRAIN_S)  # what was sent before the unplug reached the host
                port.unplug()
                counts["unplugs"] += 1
            counts["unplugged"] += 1
            return False
        if not port.plugged:
            port.replug()
            if self.wait_readers and wait_for_readers([port], self.stop, 0.0):
                deadline = time.monotonic() + REOPEN_SETTLE_S
                while not port.configured() and time.monotonic() < deadline and not self.stop.wait(0.005):
                    pass
                self.stop.wait(0.02)  # the reader's flush follows its set-up
        return True

    def _send(self, frames: list, due: float | None) -> bool:
        for frame in frames:
            if due is not None:
                ready = max(due + self.faults.delay(), self._line_free)
                if self.baudrate:
                    ready += 10.0 * len(frame) / self.baudrate / self.speed
                self._line_free = ready
                delay = ready - time.monotonic()
                if delay > 0 and self.stop.wait(delay):
                    return False
            if not self.wait_readers and not self.port.accepting():
                self.lost_unread += 1
                continue
            if not self.port.write(frame, self.stop):
                return False
            self.frames += 1
            if due is not None:
                self.latency.add(time.monotonic() - due)
        return True

    def finish(self, timeout_s: float | None) -> None:
        """Write what is queued, then return (the thread ends); ``timeout_s`` None: however long it takes."""
        if self.put(None, None):
            self.thread.join(timeout_s)
