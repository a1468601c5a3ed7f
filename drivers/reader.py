"""Device readers: read a transport on a thread and hand every raw chunk to the raw listeners.

A reader only reads: framing and decoding are the consumer's (:mod:`drivers.decoder`). It survives
unplug/replug and a restarted device: when the transport fails (an I/O error, or end-of-file on a
serial port) it is closed and reopened by its URL as configured (a symbolic link resolved anew on each
open) with exponential back-off until it returns or the reader is stopped; the listeners hear of each
outage and reconnection as events.

On a byte stream a read returns every byte that has arrived, so a reader given ``gather_s`` reads once
per tick of a ``gather_s`` grid on the host's monotonic clock after a read that returned data (as a USB
serial adapter's latency timer does): a read then carries the frames of that interval, and everything
downstream handles them as one batch, at the cost of up to ``gather_s`` of waiting in the port's buffer
(``hil.config.Config.read_s`` for a live trial). Readers with the same ``gather_s`` share the grid, so the consumer
wakes once a tick for all of them (a thread woken from idle pays a fixed cost that batched work amortises).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable

from drivers.codec import RawChunk, StreamEvent
from drivers.tap import RawListener
from drivers.transport import Transport, TransportError
from hil.vocabulary import StreamEventKind


def next_tick(now: float, period: float) -> float:
    """Seconds from ``now`` to the next multiple of ``period`` (a full period when ``now`` is on one)."""
    return period - now % period


class DeviceReader:
    """Reads one device until stopped: transport -> raw listeners."""

    def __init__(self, transport: Transport, raw_listeners: Iterable[RawListener] = (),
                 backoff_s: tuple[float, float] = (0.05, 2.0), gather_s: float = 0.0) -> None:
        self.transport = transport
        self.raw_listeners = list(raw_listeners)
        self.backoff_s = backoff_s
        self.gather_s = gather_s if transport.byte_stream else 0.0
        self.outages = 0  # times the transport failed after it had been open
        self.down: str | None = None  # why the port is down (its failure, then the last reopen's); None while open
        self.handing_over = False  # True while a chunk is with the listeners (one of them may hold it up)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> DeviceReader:
        """Open the transport and start the reader thread; raises :class:`TransportError` if it cannot open."""
        self.transport.open()
        self._thread = threading.Thread(target=self._run, name=f"reader-{self.transport.stream}", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        """Stop reading, close the transport and tell the listeners."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        self.transport.close()
        for listener in self.raw_listeners:
            listener.stop()

    def __enter__(self) -> DeviceReader:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                chunks = self.transport.read()
            except TransportError as exc:
                self._reconnect(exc)
                continue
            if chunks:
                for chunk in chunks:
                    self._handle(chunk)
                if self.gather_s:
                    self._stop.wait(next_tick(time.monotonic(), self.gather_s))

    def _handle(self, chunk: RawChunk) -> None:
        self.handing_over = True
        try:
            for listener in self.raw_listeners:
                listener.on_raw(chunk)
        finally:
            self.handing_over = False

    def _event(self, event: StreamEventKind, detail: str = "") -> None:
        note = StreamEvent(self.transport.stream, time.time(), event, detail)
        for listener in self.raw_listeners:
            listener.on_event(note)

    def _reconnect(self, error: TransportError) -> None:
        self.transport.close()  # released before the outage is announced
        self.outages += 1
        self.down = str(error)
        self._event(StreamEventKind.OUTAGE, self.down)
        delay, longest = self.backoff_s
        while not self._stop.wait(delay):
            try:
                self.transport.open()
            except TransportError as exc:
                self.down = str(exc)
                delay = min(2.0 * delay, longest)
            else:
                self.down = None
                self._event(StreamEventKind.RECONNECTED)
                return
