"""The paced writer: puts one emulated device's frames on its port (:mod:`emulators.ports`).

From its own thread, per frame: the faults (:mod:`emulators.faults`: damage, delay, the unplug
window; a frame of a powered-off device is not sent), then wire-time pacing at the line's baud rate,
then the write; the pulse-to-write latency goes into a :class:`drivers.latency.LatencyHistogram`.
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from typing import Any

from drivers.latency import LatencyHistogram
from emulators.faults import FaultInjector
from emulators.ports import WAIT_S, wait_for_readers
from emulators.sources import Emission

DRAIN_S = 5.0  # longest wait for a reader to take the bytes queued before an unplug, or at the end
REOPEN_FLUSH_S = 0.5  # after a replug, the longest wait for a reader to finish opening the port


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
            if not emission.powered:
                self.faults.counts["power_cycled"] += 1
                continue
            if not self._plugged(emission.t):
                continue
            written = self.frames
            if not self._send(self.faults.frames(emission.payload), due):
                return
            self.faults.counts["invalid"] += emission.invalid and self.frames > written

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
            if self.wait_readers:
                wait_for_readers([port], self.stop, flush_s=REOPEN_FLUSH_S)
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
        """Write what is queued, then return (the thread ends); ``timeout_s`` None: however long it takes.
        Stopped, the thread ends at its next frame: this waits for the frame in flight, so that
        :attr:`frames` counts every frame written."""
        if not self.put(None, None):
            with contextlib.suppress(queue.Full):  # a full queue: the thread is writing, not waiting for one
                self.queue.put_nowait((None, None))
        self.thread.join(timeout_s)
