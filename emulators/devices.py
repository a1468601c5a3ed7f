"""Emulated devices on pseudo-terminals: a sync pulse train, the KVH 1750 IMU and the ``tts1`` table output.

Each sync pulse k (k = 1, 2, ...) latches both devices: the IMU reports the increments over
((k - 1) / rate, k / rate], the table the gimbal angles at k / rate plus its latch delay; both carry k
as their counter. Frames are encoded by the drivers' codecs, so the emulator speaks exactly what the
drivers read.
"""

from __future__ import annotations

import fcntl
import os
import select
import struct
import termios
import threading
import time
import tty
from collections.abc import Iterator
from dataclasses import dataclass

from drivers.kvh1750 import STATUS_ALL_VALID
from drivers.registry import imu_codec
from drivers.tts1 import Mode, Status, Tts1Codec, status_byte
from emulators.simulation import Simulation
from hil.config import Config
from hil.samples import ImuSample, TableSample

WAIT_S = 0.1  # longest blocking step, so a stop request is seen promptly

_MODES = {"swing": Mode.SYNTHESIS, "rate": Mode.RATE, "positions": Mode.POSITION, "static": Mode.POSITION}


class PtyPort:
    """One pseudo-terminal: the emulator writes the master side; clients open :attr:`path` (the slave)."""

    def __init__(self) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no newline translation: bytes pass unchanged
        self.path = os.ttyname(slave)
        os.close(slave)  # the path stays valid while the master is open
        os.set_blocking(self.master, False)
        self._poll = select.poll()
        self._poll.register(self.master, select.POLLOUT)

    def has_reader(self) -> bool:
        """True while some client holds the slave side open (the master reports no hang-up)."""
        return not any(events & select.POLLHUP for _, events in self._poll.poll(0))

    def write(self, data: bytes, stop: threading.Event) -> bool:
        """Write all of ``data``, waiting while the kernel buffer is full; False if stopped first."""
        view = memoryview(data)
        while view:
            if stop.is_set():
                return False
            if not self._poll.poll(WAIT_S * 1000):
                continue
            try:
                view = view[os.write(self.master, view):]
            except BlockingIOError:
                continue
        return True

    def unread(self) -> int:
        """Bytes written but not yet read by the client (the slave's input queue)."""
        fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
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
        while self.has_reader() and empty < 2:
            empty = empty + 1 if self.unread() == 0 else 0
            if time.monotonic() > deadline or stop.wait(WAIT_S / 5):
                return False
        return True

    def close(self) -> None:
        """Close the master; clients then read end-of-file/EIO and the path disappears."""
        os.close(self.master)


def wait_for_readers(ports: list[PtyPort], stop: threading.Event, settle_s: float = 0.2) -> bool:
    """Wait until every port has a reader, then ``settle_s`` more (a client flushes its input while it
    opens the port); False if stopped first."""
    while not all(p.has_reader() for p in ports):
        if stop.wait(WAIT_S / 5):
            return False
    return not stop.wait(settle_s)


@dataclass(frozen=True)
class PulseFrames:
    """The bytes each device emits for one sync pulse."""

    index: int  # pulse count k
    imu: bytes
    table: bytes


def table_status(cfg: Config) -> int:
    """The ``tts1`` status byte of a table performing the configured motion with interlocks closed."""
    kind = cfg.turntable.motion.kind
    flags = Status.INTERLOCKS_CLOSED | (Status(0) if kind == "static" else Status.MOVING)
    return status_byte(flags, _MODES[kind])


def pulse_frames(cfg: Config, duration: float, chunk_s: float = 1.0) -> Iterator[PulseFrames]:
    """Encoded IMU and table frames for pulses k = 1 .. round(duration * rate), computed chunk by chunk."""
    trial = cfg.trial.model_copy(update={"duration_s": duration})
    sim = Simulation.from_config(cfg.model_copy(update={"trial": trial}))
    imu = imu_codec(cfg.imu, sim.rate_hz)
    table = Tts1Codec()
    latch_delay = cfg.turntable.latch_delay_us * 1e-6
    status = table_status(cfg)
    chunk = max(1, int(round(chunk_s * sim.rate_hz)))
    k = 0
    for batch in sim.batches(chunk):
        angles = sim.truth.angles(batch.t + latch_delay)
        for dtheta, dv, a in zip(batch.dtheta.tolist(), batch.dv.tolist(), angles.tolist()):
            k += 1
            imu_frame = imu.encode(imu.from_sample(ImuSample(k, tuple(dtheta), tuple(dv), status=STATUS_ALL_VALID)))
            table_frame = table.encode(table.from_sample(TableSample(k, tuple(a), latch_delay=latch_delay,
                                                                     status=status)))
            yield PulseFrames(k, imu_frame, table_frame)


class SyncClock:
    """Paces pulses at ``rate_hz`` times ``speed`` on the monotonic clock; ``speed`` None: no pacing."""

    def __init__(self, rate_hz: float, speed: float | None) -> None:
        if speed is not None and not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.period = None if speed is None else 1.0 / (rate_hz * speed)
        self.start = time.monotonic()

    def wait(self, k: int, stop: threading.Event) -> bool:
        """Wait until pulse k is due; False if stopped first."""
        if self.period is None:
            return not stop.is_set()
        delay = self.start + k * self.period - time.monotonic()
        if delay > 0:
            return not stop.wait(delay)
        return not stop.is_set()
