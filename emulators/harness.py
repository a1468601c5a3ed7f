"""The emulator in the caller's process: :func:`emulators.emulate.run_emulator` on a thread.

For a harness that wants the devices beside it (the in-process ``virtual`` CAN bus needs that) and
for tests: the ports are known once the constructor returns, the statistics once :meth:`join` does.
"""

from __future__ import annotations

import json
import tempfile
import threading
import time
from pathlib import Path
from typing import Self

from emulators.emulate import EmulatorStats, run_emulator
from hil.config import Config


class EmulatorThread:
    """Runs the emulated devices on a daemon thread until their duration or :meth:`close`."""

    def __init__(self, cfg: Config, speed: float | None = None, duration: float | None = None,
                 wait_readers: bool = True, timeout_s: float = 10.0) -> None:
        self.stop = threading.Event()
        self.stats: EmulatorStats | None = None
        self.error: BaseException | None = None
        self._dir = tempfile.TemporaryDirectory(prefix="hil-emulate-")
        self.ports_file = Path(self._dir.name) / "ports.json"
        self.thread = threading.Thread(target=self._run, args=(cfg, speed, duration, wait_readers),
                                       name="emulator", daemon=True)
        self.thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.ports_file.exists():
            if self.error is not None:
                raise self.error
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the emulator did not open its ports")
            time.sleep(0.01)
        self.ports: dict = json.loads(self.ports_file.read_text())

    def _run(self, cfg: Config, speed: float | None, duration: float | None, wait_readers: bool) -> None:
        try:
            self.stats = run_emulator(cfg, self.ports_file, speed, duration, self.stop, wait_readers)
        except Exception as exc:  # noqa: BLE001 - raised again by join()
            self.error = exc

    def current_ports(self) -> dict:
        """The ports as now published (a replugged pty that could not keep its name has a new one)."""
        return json.loads(self.ports_file.read_text()) if self.ports_file.exists() else self.ports

    def join(self, timeout_s: float = 30.0) -> EmulatorStats:
        """Wait for the run to end; its statistics."""
        self.thread.join(timeout_s)
        if self.thread.is_alive():
            raise TimeoutError(f"the emulator is still running after {timeout_s} s")
        self._dir.cleanup()
        if self.error is not None:
            raise self.error
        return self.stats

    def close(self) -> EmulatorStats:
        """Stop the devices now; their statistics."""
        self.stop.set()
        return self.join()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(10)
        self._dir.cleanup()
