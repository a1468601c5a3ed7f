"""Emulated devices: frame sources on device clocks, and writers that put the frames on ptys or a CAN bus.

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
import fcntl
import os
import queue
import select
import struct
import termios
import threading
import time
import tty
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from drivers.kvh1750 import STATUS_ALL_VALID
from drivers.transport import open_can_bus
from drivers.tts1 import Status, Tts1Codec
from emulators.faults import FaultInjector
from emulators.sensor_errors import SensorErrorModel
from emulators.servo import Servo
from emulators.timing import DeviceClock
from emulators.truth import Truth
from hil.samples import ImuSample, TableSample

WAIT_S = 0.1  # longest blocking step, so a stop request is seen promptly
DRAIN_S = 5.0  # longest wait for a reader to take the bytes queued before an unplug
REOPEN_SETTLE_S = 0.5  # after a replug, the longest wait for a reader to finish opening the port
PROBE_SPEED = termios.B50  # a fresh pty's line speed, so the reader's own settings show when it configures it
LATENCY_BIN_S = 10e-6  # resolution of the write-latency histogram
LATENCY_BINS = 10_000  # up to 100 ms; later writes land in the last bin


class PtyPort:
    """One pseudo-terminal: the emulator writes the master side; clients open :attr:`path` (the slave).

    With ``link`` the port is published as that symbolic link to the slave, like a udev by-id name:
    :meth:`unplug` closes the master, as pulling a USB adapter removes its device (readers get an
    error, the link dangles), and :meth:`replug` opens a new pty and points the link at it, so a
    reader that reopens the link finds the device again, never another program's pty that took the
    old number.
    """

    def __init__(self, link: Path | None = None) -> None:
        self.link = link
        self._open()

    def _open(self) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no newline translation: bytes pass unchanged
        self.tty = os.ttyname(slave)
        os.close(slave)  # the slave stays valid while the master is open
        os.set_blocking(self.master, False)
        self.plugged = True
        attrs = termios.tcgetattr(self.master)  # on a pty master: the slave's settings
        attrs[4] = attrs[5] = PROBE_SPEED
        termios.tcsetattr(self.master, termios.TCSANOW, attrs)
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".new")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(self.tty)
            os.replace(tmp, self.link)

    @property
    def path(self) -> str:
        return str(self.link) if self.link is not None else self.tty

    def _events(self, timeout_ms: float) -> list[int]:
        """The master's poll events (a poll object per call: the writer thread and the drain may ask at once)."""
        poll = select.poll()
        poll.register(self.master, select.POLLOUT)
        return [events for _, events in poll.poll(timeout_ms)]

    def has_reader(self) -> bool:
        """True while some client holds the slave side open (the master reports no hang-up)."""
        return not any(events & select.POLLHUP for events in self._events(0))

    def accepting(self) -> bool:
        """True when a reader holds the port and its input queue has room: a UART's bytes would arrive."""
        events = self._events(0)
        return bool(events) and not any(e & select.POLLHUP for e in events) and any(e & select.POLLOUT for e in events)

    def configured(self) -> bool:
        """True once a reader has set the line up (a serial library does, and then flushes its input)."""
        return termios.tcgetattr(self.master)[5] != PROBE_SPEED

    def write(self, data: bytes, stop: threading.Event) -> bool:
        """Write all of ``data``, waiting while the kernel buffer is full; False if stopped first."""
        view = memoryview(data)
        while view:
            if stop.is_set():
                return False
            if not self._events(WAIT_S * 1000):
                continue
            try:
                view = view[os.write(self.master, view):]
            except BlockingIOError:
                continue
        return True

    def unread(self) -> int:
        """Bytes written but not yet read by the client (the slave's input queue)."""
        fd = os.open(self.tty, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0" * 4))[0]
        finally:
            os.close(fd)

    def drain(self, stop: threading.Event, timeout_s: float) -> bool:
        """Wait until the client has read everything or left (closing the master discards unread bytes).

        The queue must read empty on two checks in a row: bytes still in the kernel's flip buffer are
        not counted yet.
        """
        deadline = time.monotonic() + timeout_s
        empty = 0
        while self.plugged and self.has_reader() and empty < 2:
            empty = empty + 1 if self.unread() == 0 else 0
            if time.monotonic() > deadline or stop.wait(WAIT_S / 5):
                return False
        return True

    def unplug(self) -> None:
        """Close the master; clients then read end-of-file/EIO and the slave disappears."""
        if self.plugged:
            os.close(self.master)
            self.plugged = False

    def replug(self) -> None:
        self._open()

    def close(self) -> None:
        """Unplug for good: the link goes too."""
        self.unplug()
        if self.link is not None:
            self.link.unlink(missing_ok=True)


class CanPort:
    """A python-can bus the IMU sends on; "unplugged" it is silent."""

    def __init__(self, interface: str, channel: str) -> None:
        self.interface, self.channel = interface, channel
        self.bus = open_can_bus(interface, channel)
        self.plugged = True

    @property
    def path(self) -> dict[str, str]:
        return {"interface": self.interface, "channel": self.channel}

    def has_reader(self) -> bool:
        return True  # a bus does not know its listeners

    def accepting(self) -> bool:
        return True

    def configured(self) -> bool:
        return True

    def write(self, messages: list, stop: threading.Event) -> bool:
        for m in messages:
            self.bus.send(m)
        return not stop.is_set()

    def drain(self, stop: threading.Event, timeout_s: float) -> bool:
        return True

    def unplug(self) -> None:
        self.plugged = False

    def replug(self) -> None:
        self.plugged = True

    def close(self) -> None:
        self.bus.shutdown()


def wait_for_readers(ports: list, stop: threading.Event, settle_s: float = 0.2) -> bool:
    """Wait until every port has a reader, then ``settle_s`` more (a client flushes its input while it
    opens the port); False if stopped first."""
    while not all(p.has_reader() for p in ports):
        if stop.wait(WAIT_S / 5):
            return False
    return not stop.wait(settle_s)


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
