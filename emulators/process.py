"""The emulator as a process (``hil emulate``): run the emulated devices until stopped, signalled or done.

Run it in its own process (``python -m emulators CONFIG [--ports-file PATH] [--link-dir DIR]
[--stats-file PATH] [--speed X|max] [--duration S]``, or :func:`spawn_emulator`, which waits for the
ports with :func:`wait_for_ports`); clients find the ports in the JSON ports file or on stdout::

    {"imu": "/dev/pts/N" | {"interface": "udp_multicast", "channel": "239.0.0.1"},
     "turntable_data": "/dev/pts/M", "turntable_cmd": "socket://127.0.0.1:PORT",
     "chamber": "/dev/pts/K", "power": "TCPIP::127.0.0.1::PORT::SOCKET"}   # the last two with environment

With ``--link-dir DIR`` the serial ports are published as stable symbolic links to their ptys,
``DIR/imu`` and ``DIR/turntable_data`` (as udev's by-id names), and named so; a later emulator on the
same DIR points them at its own ptys. Without it, a device configured to unplug
(``faults.unplug_at_s``) is published so in a private ``/tmp/hil-emulate-XXXX``. A replug points the
link at the new pty. The IMU speaks ``imu.protocol`` (a serial protocol on a pty, can-dbc on
the python-can bus of ``imu.can``); the table sends ``tts1`` on a pty and answers its controller's language on
the TCP port. The run's statistics (:class:`emulators.bench.EmulatorStats`) go to stderr as one line a device
at exit (:mod:`emulators.command`), and to ``--stats-file`` as JSON. The devices themselves are
:class:`emulators.bench.Bench`.
"""

from __future__ import annotations

import ctypes
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from emulators.bench import Bench, EmulatorStats, SyncClock
from emulators.ports import wait_for_readers
from emulators.paced_writer import DRAIN_S
from hil.config import Config, ConfigError

PR_SET_PDEATHSIG = 1  # prctl option: a signal for the child when its parent dies
POLL_S = 0.01  # how often the ports file is looked for


def _write_json(path: Path, data: dict) -> None:
    """Write JSON atomically, so a reader never sees a partial file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data) + "\n")
    os.replace(tmp, path)


@dataclass(frozen=True)
class EmulatorRun:
    """How the emulated devices run, the options of ``hil emulate``: ``speed`` a multiple of real time as text, or
    ``max`` (as fast as the readers take the bytes); ``duration`` s of trial time (None: ``trial.duration_s``); with
    ``wait_readers`` the pulse train waits for a reader on each pty; with ``hold`` the devices stay powered after the
    train until stopped; the statistics to ``stats_file``; the serial ports published as links in ``link_dir``."""

    speed: str = "max"
    duration: float | None = None
    wait_readers: bool = False
    hold: bool = False
    stats_file: Path | None = None
    link_dir: Path | None = None

    @property
    def pace(self) -> float | None:
        """The multiple of real time, None for ``max`` (:func:`parse_speed`)."""
        return parse_speed(self.speed)

    def arguments(self) -> list[str]:
        """These options on the command line of ``python -m emulators``."""
        args = ["--speed", self.speed]
        for option, value in (("--duration", self.duration), ("--stats-file", self.stats_file),
                              ("--link-dir", self.link_dir)):
            if value is not None:
                args += [option, str(value)]
        return args + ["--wait-readers"] * self.wait_readers + ["--hold"] * self.hold


def run_emulator(cfg: Config, run: EmulatorRun = EmulatorRun(), ports_file: Path | None = None,
                 stop_event: threading.Event | None = None) -> EmulatorStats:
    """Emulate the IMU and the turntable of ``cfg`` as ``run`` says until its duration, a signal or ``stop_event``;
    the ports to ``ports_file`` (JSON) and stdout once open.

    Without ``run.wait_readers`` the pulse train starts at once, and a port nobody reads loses its frames (counted);
    with it, once a client has opened each pty (as a table enables its sync output when the host is ready), and it
    resumes after an unplug once a client has reopened the port. From the main thread, SIGTERM, SIGINT and SIGHUP
    set the stop event. The statistics go to ``run.stats_file`` at the end, stopped or not; with ``run.hold`` the
    devices stay powered after the pulse train (the table answers commands, the data ports are silent) until
    stopped, as a table stays on its base after a trial: the file is written when the train has ended and rewritten
    at exit with the commands received meanwhile. With ``run.link_dir`` the serial ports are published as links
    there (:class:`emulators.bench.Bench`). Ports, command socket and ports file are released on return.
    """
    duration = cfg.trial.duration_s if run.duration is None else run.duration
    if duration is None:
        raise ConfigError("trial.duration_s: required key is missing (or give --duration)")
    stop = stop_event or threading.Event()
    bench: Bench | None = None
    owner = _Owner(os.getppid())
    with _SignalsStop(stop):
        try:
            bench = Bench(cfg, duration, run.pace, stop, run.wait_readers, run.link_dir)
            print(json.dumps(bench.names()), flush=True)
            if ports_file is not None:
                _write_json(ports_file, bench.names())
            stats = _pulse_train(bench, stop, run, lambda ended: owner.write(run.stats_file, ended.as_dict()))
            owner.write(run.stats_file, stats.as_dict())
            return stats
        finally:
            if bench is not None:
                bench.close()
            if ports_file is not None:
                ports_file.unlink(missing_ok=True)


def _pulse_train(bench: Bench, stop: threading.Event, run: EmulatorRun,
                 train_ended: Callable[[EmulatorStats], None]) -> EmulatorStats:
    """The pulse train of :func:`run_emulator` until done or stopped, the bytes written left to the readers,
    and with ``run.hold`` the devices kept up until stopped (``train_ended`` told of the train's statistics first);
    the statistics."""
    hold = run.hold
    if run.wait_readers and not wait_for_readers(bench.ptys(), stop):
        return bench.stats(0, 0.0, True)
    clock = SyncClock(run.pace)
    pulses = bench.pulse_loop(clock, stop)
    # held devices wait for their reader however slow: the stats file then means "all was read"
    for writer in bench.writers.values():
        writer.finish(None if hold else DRAIN_S)
    for port in bench.ports.values():
        port.drain(stop, math.inf if hold else DRAIN_S)
    elapsed, stopped = time.monotonic() - clock.start, stop.is_set()
    if hold:
        train_ended(bench.stats(pulses, elapsed, stopped, clock.due(0.0)))  # the stats file: the train has ended
        stop.wait()
    return bench.stats(pulses, elapsed, stopped, clock.due(0.0))  # held: with the commands received meanwhile


class _Owner:
    """The process that started the emulator (``parent``, its pid). Once it is gone (a harness killed outright:
    its death signal stops the emulator), the emulator writes no more statistics: they are in the harness's
    directory, where the next harness (a plan resumed at once) may already have started its own, and would tell it
    that its devices' run has ended. The ports file is still removed on the way out (spawn_emulator removes a
    stale one before it starts the next)."""

    def __init__(self, parent: int) -> None:
        self.parent = parent

    def write(self, path: Path | None, doc: dict) -> None:
        """``doc`` to ``path`` (JSON; None: nowhere) while the parent lives."""
        if path is not None and os.getppid() == self.parent:
            _write_json(path, doc)


class _SignalsStop:
    """From the main thread, SIGTERM, SIGINT and SIGHUP set ``stop``. The handler itself does nothing: the
    interpreter writes the signal to a wake-up pipe that a watcher thread turns into ``stop.set()``, since
    a handler calling ``Event.set`` while the main thread is inside that Event's lock would deadlock."""

    SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop
        self._previous: dict[int, object] = {}
        self._pipe: tuple[int, int] | None = None
        self._wakeup = -1

    def __enter__(self) -> _SignalsStop:
        if threading.current_thread() is not threading.main_thread():
            return self
        self._pipe = os.pipe()
        os.set_blocking(self._pipe[1], False)
        self._wakeup = signal.set_wakeup_fd(self._pipe[1], warn_on_full_buffer=False)
        for sig in self.SIGNALS:
            self._previous[sig] = signal.signal(sig, lambda *_: None)
        threading.Thread(target=self._watch, args=(self._pipe[0],), name="emulate-signals", daemon=True).start()
        return self

    def _watch(self, fd: int) -> None:
        while data := os.read(fd, 64):
            if any(b in self.SIGNALS for b in data):
                self.stop.set()
        os.close(fd)

    def __exit__(self, *exc: object) -> None:
        if self._pipe is None:
            return
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        signal.set_wakeup_fd(self._wakeup)
        os.close(self._pipe[1])  # the watcher reads end-of-file and ends
        self._pipe = None


def parse_speed(text: str) -> float | None:
    """``max`` -> None (no pacing), otherwise a positive multiple of real time."""
    if text == "max":
        return None
    value = float(text)
    if not value > 0:
        raise ValueError(f"speed must be positive or 'max', got {text!r}")
    return value


class EmulatorError(RuntimeError):
    """The emulator process could not start its devices; the message is the emulator's own."""


def _die_with_parent() -> None:
    """In the child, before exec: receive SIGTERM when the parent dies (Linux), so no emulator outlives
    a harness that was killed outright."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def spawn_emulator(config: Path, ports_file: Path, run: EmulatorRun = EmulatorRun(wait_readers=True),
                   log_file: Path | None = None, timeout_s: float = 20.0) -> tuple[subprocess.Popen, dict]:
    """Start ``python -m emulators`` on ``config`` in its own process, run as ``run`` says; returns it and its ports
    once open (within ``timeout_s``).

    The child runs in its own session, so a Ctrl-C or a hang-up of the terminal reaches only the
    harness, which turns the table off before it stops the devices; it ends with the harness. With
    ``run.hold`` it keeps its devices up after the pulse train until stopped (see :func:`run_emulator`). Its
    stderr (the stats at the end, any error) goes to ``log_file`` when given. Raises
    :class:`EmulatorError` with the emulator's last line when it exits before opening its ports.
    """
    ports_file.unlink(missing_ok=True)
    if run.stats_file is not None:
        run.stats_file.unlink(missing_ok=True)  # its appearance tells that the pulse train has ended
    cmd = [sys.executable, "-m", "emulators", str(config), "--ports-file", str(ports_file), *run.arguments()]
    with open(log_file, "w+b") if log_file is not None else tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
                                preexec_fn=_die_with_parent if sys.platform == "linux" else None)
        ports = wait_for_ports(ports_file, lambda: proc.poll() is None, timeout_s)
        if ports is None:
            proc.kill()
            proc.wait()
            log.seek(0)
            lines = log.read().decode(errors="replace").strip().splitlines()
            raise EmulatorError(lines[-1].removeprefix("emulator: error: ") if lines else
                                f"the emulator did not open its ports (exit code {proc.returncode})")
    return proc, ports


def wait_for_ports(ports_file: Path, running: Callable[[], bool], timeout_s: float) -> dict | None:
    """The ports JSON once the emulator has written ``ports_file``; None when ``running()`` turns False
    or ``timeout_s`` passes first."""
    deadline = time.monotonic() + timeout_s
    while not ports_file.exists():
        if not running() or time.monotonic() > deadline:
            return None
        time.sleep(POLL_S)
    return json.loads(ports_file.read_text())


def stop_emulator(process: subprocess.Popen) -> None:
    """End a spawned emulator: SIGTERM, then SIGKILL if it has not gone within 5 s."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(5.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
