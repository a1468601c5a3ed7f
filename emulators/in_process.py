"""The emulator in the caller's process: :func:`emulators.process.run_emulator` on a thread.

For a harness that wants the devices beside it (the in-process ``virtual`` CAN bus needs that) and
for tests: the ports are known once the constructor returns, the statistics once :meth:`join` does.
"""

from __future__ import annotations

import tempfile
import threading
from pathlib import Path
from typing import Self

from emulators.bench import EmulatorStats
from emulators.process import EmulatorRun, run_emulator, wait_for_ports
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
        ports = wait_for_ports(self.ports_file, lambda: self.error is None and self.thread.is_alive(), timeout_s)
        if ports is None:
            if self.error is not None:
                raise self.error
            raise RuntimeError("the emulator did not open its ports")
        self.ports: dict = ports

    def _run(self, cfg: Config, speed: float | None, duration: float | None, wait_readers: bool) -> None:
        try:
            run = EmulatorRun("max" if speed is None else repr(speed), duration, wait_readers)
            self.stats = run_emulator(cfg, run, self.ports_file, self.stop)
        except Exception as exc:  # noqa: BLE001 - raised again by join()
            self.error = exc

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
