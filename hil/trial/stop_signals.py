"""Signals that end a trial: SIGINT (Ctrl-C), SIGTERM and SIGHUP (a closed terminal) ask it to stop.

A trial that commands a turntable must turn it off on every way out, so these signals never unwind
the stack mid-command: the first one is noted and the trial's loop ends at its next step (as at a
normal end: table off, recorder closed, outputs for the data so far); a repeated one during that
shutdown is only acknowledged, so the table is still sent Off first.
"""

from __future__ import annotations

import os
import signal
import threading
from types import FrameType

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopSignals:
    """Context manager (main thread) turning the stop signals into :attr:`received`, the first one's name.

    The handler only assigns and writes to stderr with one system call: it runs between two bytecodes of
    the main thread, which may hold a lock (an Event's, a buffered stream's) the handler must not take.
    """

    def __init__(self) -> None:
        self.received: str | None = None
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for sig in STOP_SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        if self.received is None:
            self.received = name
            note = f"hil: {name}: ending the trial (turntable off, outputs kept)\n"
        else:
            note = f"hil: {name}: already ending the trial; the turntable is turned off first\n"
        os.write(2, note.encode())
