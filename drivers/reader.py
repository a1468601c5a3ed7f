"""Device sessions: read a transport on a thread, tap raw chunks, frame, decode, hand on samples.

A session survives unplug/replug: when the transport fails it is closed and reopened with
exponential back-off until it returns or the session is stopped; each such outage is counted.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable

from drivers.codec import Codec, Counters, DecodeError, Framer, RawChunk, StreamEvent
from drivers.tap import RawListener, SampleListener
from drivers.transport import Transport, TransportError


class DeviceSession:
    """Reads one device until stopped: transport -> raw listeners -> framer -> codec -> sample listeners."""

    def __init__(self, transport: Transport, codec: Codec, raw_listeners: Iterable[RawListener] = (),
                 sample_listeners: Iterable[SampleListener] = (), backoff_s: tuple[float, float] = (0.05, 2.0)
                 ) -> None:
        self.transport = transport
        self.codec = codec
        self.framer: Framer = codec.framer()
        self.raw_listeners = list(raw_listeners)
        self.sample_listeners = list(sample_listeners)
        self.backoff_s = backoff_s
        self.outages = 0  # times the transport failed after it had been open
        self.last_error: str | None = None
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def counters(self) -> Counters:
        return self.framer.counters

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    def wait_connected(self, timeout: float) -> bool:
        """True once the transport is open (again)."""
        return self._connected.wait(timeout)

    def start(self) -> DeviceSession:
        """Open the transport and start the reader thread; raises :class:`TransportError` if it cannot open."""
        self.transport.open()
        self._connected.set()
        self._thread = threading.Thread(target=self._run, name=f"session-{self.transport.stream}", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        """Stop reading, close the transport and tell the listeners."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        self.transport.close()
        self._connected.clear()
        for listener in (*self.raw_listeners, *self.sample_listeners):
            listener.stop()

    def __enter__(self) -> DeviceSession:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                chunk = self.transport.read()
            except TransportError as exc:
                self._reconnect(exc)
                continue
            if chunk is not None:
                self._handle(chunk)

    def _handle(self, chunk: RawChunk) -> None:
        for listener in self.raw_listeners:
            listener.on_raw(chunk)
        if not self.sample_listeners:
            return  # raw capture only: the consumer frames the chunks itself
        for decoded in self.framer.feed_chunk(chunk):
            try:
                sample = self.codec.to_sample(decoded)
            except DecodeError:
                self.framer.counters.corrupt += 1
                continue
            for listener in self.sample_listeners:
                listener.on_sample(sample)

    def _event(self, event: str, detail: str = "") -> None:
        note = StreamEvent(self.transport.stream, time.time(), event, detail)
        for listener in self.raw_listeners:
            listener.on_event(note)

    def _reconnect(self, error: TransportError) -> None:
        self.outages += 1
        self.last_error = str(error)
        self._event("outage", str(error))
        self._connected.clear()
        self.transport.close()
        self.framer.reset()
        delay, longest = self.backoff_s
        while not self._stop.wait(delay):
            try:
                self.transport.open()
            except TransportError as exc:
                self.last_error = str(exc)
                delay = min(2.0 * delay, longest)
            else:
                self._connected.set()
                self._event("reconnected")
                return
