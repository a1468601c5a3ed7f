"""``hil emulate``: run the emulated devices on pseudo-terminals until stopped, signalled or done.

Run it in its own process (``python -m emulators.emulate CONFIG [--ports-file PATH] [--speed X|max]
[--duration S]``, or :func:`spawn_emulator`); clients find the ports in the JSON ports file
(``{"imu": "/dev/pts/N", "turntable_data": "/dev/pts/M"}``) or on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from emulators.devices import PtyPort, SyncClock, pulse_frames, wait_for_readers
from hil.config import Config, ConfigError, load_config

DRAIN_S = 5.0  # longest wait at the end for readers to take the bytes still queued


@dataclass(frozen=True)
class EmulatorStats:
    """What one emulator run produced."""

    pulses: int
    elapsed_s: float
    stopped: bool  # True when stopped by a signal or the stop event before the duration


def _write_ports(path: Path, ports: dict[str, str]) -> None:
    """Write the ports atomically, so a reader never sees a partial file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(ports) + "\n")
    os.replace(tmp, path)


def run_emulator(cfg: Config, ports_file: Path | None = None, speed: float | None = None,
                 duration: float | None = None, stop_event: threading.Event | None = None,
                 wait_readers: bool = True) -> EmulatorStats:
    """Emulate the IMU and the turntable data output on ptys until the duration, a signal or ``stop_event``.

    ``speed`` is the multiple of real time (None: as fast as the readers take the bytes); ``duration``
    (s) defaults to ``trial.duration_s``. With ``wait_readers`` the pulse train starts once a client has
    opened each port (as a table enables its sync output when the host is ready); otherwise at once. From the main thread, SIGTERM and SIGINT set the stop event.
    The ptys are closed and the ports file removed on return.
    """
    if cfg.imu.protocol != "kvh1750":
        raise ConfigError(f"imu.protocol: the emulator supports kvh1750 so far, not {cfg.imu.protocol!r}")
    duration = cfg.trial.duration_s if duration is None else duration
    if duration is None:
        raise ConfigError("trial.duration_s: required key is missing (or give --duration)")
    stop = stop_event or threading.Event()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            previous[sig] = signal.signal(sig, lambda *_: stop.set())
    imu, table = PtyPort(), PtyPort()
    pulses = 0
    try:
        ports = {"imu": imu.path, "turntable_data": table.path}
        print(json.dumps(ports), flush=True)
        if ports_file is not None:
            _write_ports(ports_file, ports)
        if wait_readers and not wait_for_readers([imu, table], stop):
            return EmulatorStats(0, 0.0, True)
        clock = SyncClock(cfg.imu_rate_hz, speed)
        for frames in pulse_frames(cfg, duration):
            if not (clock.wait(frames.index, stop) and imu.write(frames.imu, stop)
                    and table.write(frames.table, stop)):
                break
            pulses = frames.index
        for port in (imu, table):
            port.drain(stop, DRAIN_S)
        return EmulatorStats(pulses, time.monotonic() - clock.start, stop.is_set())
    finally:
        imu.close()
        table.close()
        if ports_file is not None:
            ports_file.unlink(missing_ok=True)
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def parse_speed(text: str) -> float | None:
    """``max`` -> None (no pacing), otherwise a positive multiple of real time."""
    if text == "max":
        return None
    value = float(text)
    if not value > 0:
        raise ValueError(f"speed must be positive or 'max', got {text!r}")
    return value


def spawn_emulator(config: Path, ports_file: Path, speed: str = "max", duration: float | None = None,
                   timeout_s: float = 20.0) -> tuple[subprocess.Popen, dict[str, str]]:
    """Start ``python -m emulators.emulate`` in its own process; returns it and its ports once open."""
    ports_file.unlink(missing_ok=True)
    cmd = [sys.executable, "-m", "emulators.emulate", str(config), "--ports-file", str(ports_file),
           "--speed", speed]
    if duration is not None:
        cmd += ["--duration", str(duration)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + timeout_s
    while not ports_file.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            proc.wait()
            raise RuntimeError(f"emulator did not open its ports (exit code {proc.returncode})")
        time.sleep(0.02)
    return proc, json.loads(ports_file.read_text())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emulators.emulate", description=__doc__.splitlines()[0])
    parser.add_argument("config", type=Path)
    parser.add_argument("--ports-file", type=Path)
    parser.add_argument("--speed", type=parse_speed, default=1.0, help="multiple of real time, or max")
    parser.add_argument("--duration", type=float, help="s; default trial.duration_s")
    parser.add_argument("--no-wait", action="store_true", help="start the pulse train without waiting for readers")
    args = parser.parse_args(argv)
    stats = run_emulator(load_config(args.config), args.ports_file, args.speed, args.duration,
                         wait_readers=not args.no_wait)
    print(json.dumps({"pulses": stats.pulses, "elapsed_s": round(stats.elapsed_s, 3), "stopped": stats.stopped}),
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
