"""``hil emulate``: run the emulated devices until stopped, signalled or done.

Run it in its own process (``python -m emulators.emulate CONFIG [--ports-file PATH] [--stats-file PATH]
[--speed X|max] [--duration S]``, or :func:`spawn_emulator`); clients find the ports in the JSON ports
file or on stdout::

    {"imu": "/dev/pts/N" | {"interface": "udp_multicast", "channel": "239.0.0.1"},
     "turntable_data": "/dev/pts/M", "turntable_cmd": "socket://127.0.0.1:PORT"}

A device configured to unplug (``faults.unplug_at_s``) is published as a stable symbolic link to its
pty, ``/tmp/hil-emulate-XXXX/imu`` or ``.../turntable_data`` (as udev's by-id names), which the replug
points at the new pty. The IMU speaks ``imu.protocol`` (kvh1750 and xsens-mtdata2 on a pty, can-dbc on the python-can bus of
``imu.can``); the table sends ``tts1`` on a pty and answers ``acl`` on the TCP port. The run's
statistics (:class:`EmulatorStats`) go to stderr as JSON at exit, and to ``--stats-file``.
"""

from __future__ import annotations

import argparse
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
from dataclasses import asdict, dataclass, field
from pathlib import Path

from drivers.acl import AclCommand
from drivers.registry import imu_codec
from emulators.acl_server import AclServer
from emulators.devices import DeviceStream, DeviceWriter, ImuSource, TableSource
from emulators.faults import ByteDamage, CanDamage, FaultInjector
from emulators.ports import CanPort, PtyPort, wait_for_readers
from emulators.servo import Servo
from emulators.simulation import Simulation
from emulators.timing import DeviceClock
from hil.config import Config, ConfigError, load_config
from hil.samples import ImuSample

DRAIN_S = 5.0  # longest wait at the end for readers to take the bytes still queued
CHUNK_S = 0.25  # frames computed ahead, trial seconds
PR_SET_PDEATHSIG = 1  # prctl option: a signal for the child when its parent dies
BITS_PER_BYTE = 10  # 8N1
PROBE = ImuSample(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), device_time=0.0)  # sizes an IMU frame


@dataclass(frozen=True)
class DeviceStats:
    """What one emulated device wrote: frames, injected faults per kind, pulse-to-write latency, and the
    frames lost because no reader took them (``hil emulate`` without ``--wait-readers``)."""

    frames: int
    faults: dict[str, int]
    latency_p50_ms: float | None  # None when unpaced (speed max)
    latency_p99_ms: float | None
    lost_unread: int = 0


@dataclass(frozen=True)
class EmulatorStats:
    """What one emulator run produced."""

    pulses: int
    elapsed_s: float
    stopped: bool  # True when stopped by a signal or the stop event before the duration
    devices: dict[str, DeviceStats] = field(default_factory=dict)  # keys "imu", "turntable_data"
    table_commands: dict[str, int] = field(default_factory=dict)  # acl commands received, by header
    table_modes_off: int = 0  # ``:Mode ALL,Off`` commands the table accepted
    table_modes: str = ""  # the table's modes at the end (``:Mode? ALL``: inner, middle, outer)

    def as_dict(self) -> dict:
        return asdict(self)


class SyncClock:
    """Paces trial time at ``speed`` times real time on the monotonic clock; ``speed`` None: no pacing."""

    def __init__(self, speed: float | None) -> None:
        if speed is not None and not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.speed = speed
        self.start = time.monotonic()

    def due(self, t: float) -> float | None:
        """The monotonic time at which trial time t is due (None: unpaced)."""
        return None if self.speed is None else self.start + t / self.speed

    def wait_until(self, t: float, stop: threading.Event) -> bool:
        """Wait until trial time t is due; False if stopped first."""
        due = self.due(t)
        delay = 0.0 if due is None else due - time.monotonic()
        return not stop.wait(delay) if delay > 0 else not stop.is_set()


def _write_json(path: Path, data: dict) -> None:
    """Write JSON atomically, so a reader never sees a partial file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data) + "\n")
    os.replace(tmp, path)


def check_baudrate(name: str, frame_bytes: int, rate_hz: float, baudrate: int) -> None:
    """Raise :class:`ConfigError` when frames of ``frame_bytes`` at ``rate_hz`` do not fit the line."""
    needed = frame_bytes * BITS_PER_BYTE * rate_hz
    if needed > baudrate:
        raise ConfigError(f"{name}.baudrate: {frame_bytes}-byte frames at {rate_hz:g} Hz need {needed:.0f} baud "
                          f"(8N1), more than the configured {baudrate}; raise the baudrate or lower the rate")


class _Devices:
    """The emulated IMU and table of one run: servo, frame streams, ports, writers, command server."""

    def __init__(self, cfg: Config, duration: float, speed: float | None, stop: threading.Event,
                 wait_readers: bool) -> None:
        rate = cfg.imu_rate_hz
        sim = Simulation.from_config(cfg.model_copy(update={"trial": cfg.trial.model_copy(
            update={"duration_s": duration})}))
        imu_cfg = cfg.imu
        codec = imu_codec(imu_cfg, rate)
        imu_clock = DeviceClock(rate, imu_cfg.latch_delay_us * 1e-6, imu_cfg.timing)
        table_clock = DeviceClock(cfg.table_counter_rate_hz, cfg.turntable.latch_delay_us * 1e-6,
                                  cfg.turntable.timing, cfg.table_counts_per_frame)
        seed = cfg.trial.seed
        imu_source = ImuSource(imu_clock, seed, codec, sim.errors, device_time=imu_cfg.protocol == "xsens-mtdata2")
        table_source = TableSource(table_clock, seed)
        self.servo = Servo(cfg.turntable, rate, sim.truth.motion)
        self.streams = {name: DeviceStream(source, sim.truth, source.clock.ticks(duration),
                                           max(1, round(CHUNK_S / source.clock.period)))
                        for name, source in (("imu", imu_source), ("turntable_data", table_source))}
        self.synced = [n for n, c in (("imu", imu_clock), ("turntable_data", table_clock))
                       if not c.timing.free_running] or ["imu"]
        self.ports: dict = {}
        self.writers: dict[str, DeviceWriter] = {}
        self.server: AclServer | None = None
        unplugging = [f.unplug_at_s is not None for f in (imu_cfg.faults, cfg.turntable.faults)]
        self._links = tempfile.TemporaryDirectory(prefix="hil-emulate-") if any(unplugging) else None

        def pty(name: str, unplugs: bool) -> PtyPort:
            return PtyPort(Path(self._links.name) / name if unplugs else None)

        try:
            if imu_cfg.protocol == "can-dbc":
                imu_port, imu_damage, imu_baud = CanPort(imu_cfg.can.interface, imu_cfg.can.channel), CanDamage(), None
            else:
                check_baudrate("imu", len(codec.encode(codec.from_sample(PROBE))), rate, imu_cfg.baudrate)
                imu_port, imu_damage, imu_baud = pty("imu", unplugging[0]), ByteDamage(), imu_cfg.baudrate
            self.ports["imu"] = imu_port
            check_baudrate("turntable", 24, cfg.trial.rate_hz, cfg.turntable.baudrate)
            self.ports["turntable_data"] = pty("turntable_data", unplugging[1])
            self.server = AclServer(self.servo)
            for k, (name, damage, baud, faults) in enumerate((
                    ("imu", imu_damage, imu_baud, imu_cfg.faults),
                    ("turntable_data", ByteDamage(), cfg.turntable.baudrate, cfg.turntable.faults))):
                self.writers[name] = DeviceWriter(name, self.ports[name], FaultInjector(faults, damage, seed, k),
                                                  baud, speed, stop, wait_readers)
        except BaseException:
            self.close()
            raise

    def names(self) -> dict:
        """The ports JSON."""
        return {"imu": self.ports["imu"].path, "turntable_data": self.ports["turntable_data"].path,
                "turntable_cmd": self.server.url}

    def close(self) -> None:
        if self.server is not None:
            self.server.close()
        for port in self.ports.values():
            port.close()
        if self._links is not None:
            self._links.cleanup()


def run_emulator(cfg: Config, ports_file: Path | None = None, speed: float | None = None,
                 duration: float | None = None, stop_event: threading.Event | None = None,
                 wait_readers: bool = False, stats_file: Path | None = None, hold: bool = False) -> EmulatorStats:
    """Emulate the IMU and the turntable until the duration, a signal or ``stop_event``.

    ``speed`` is the multiple of real time (None: as fast as the readers take the bytes); ``duration``
    (s) defaults to ``trial.duration_s``. With ``wait_readers`` the pulse train starts once a client has
    opened each pty (as a table enables its sync output when the host is ready), and resumes after an
    unplug once a client has reopened the port; otherwise at once, and a port nobody reads loses its
    frames (counted). From the main thread, SIGTERM, SIGINT and SIGHUP set the stop event. The
    statistics go to ``stats_file`` when the pulse train has ended; with ``hold`` the devices then stay
    powered (the table answers ``acl``, the data ports are silent) until stopped, as a table stays on
    its base after a trial, and the file is rewritten with the commands received meanwhile. Ports,
    command socket and ports file are released on return.
    """
    duration = cfg.trial.duration_s if duration is None else duration
    if duration is None:
        raise ConfigError("trial.duration_s: required key is missing (or give --duration)")
    stop = stop_event or threading.Event()
    devices: _Devices | None = None
    with _SignalsStop(stop):
        try:
            devices = _Devices(cfg, duration, speed, stop, wait_readers)
            print(json.dumps(devices.names()), flush=True)
            if ports_file is not None:
                _write_json(ports_file, devices.names())
            ptys = [p for p in devices.ports.values() if isinstance(p, PtyPort)]
            if wait_readers and not wait_for_readers(ptys, stop):
                return _stats(devices, 0, 0.0, True)
            clock = SyncClock(speed)
            pulses = _pulse_loop(devices, clock, stop)
            # held devices wait for their reader however slow: the stats file then means "all was read"
            for writer in devices.writers.values():
                writer.finish(None if hold else DRAIN_S)
            for port in devices.ports.values():
                port.drain(stop, math.inf if hold else DRAIN_S)
            elapsed, stopped = time.monotonic() - clock.start, stop.is_set()
            stats = _stats(devices, pulses, elapsed, stopped)
            if hold:
                if stats_file is not None:
                    _write_json(stats_file, stats.as_dict())  # tells that the pulse train has ended
                stop.wait()
                stats = _stats(devices, pulses, elapsed, stopped)  # with the commands received meanwhile
            if stats_file is not None:
                _write_json(stats_file, stats.as_dict())
            return stats
        finally:
            if devices is not None:
                devices.close()
            if ports_file is not None:
                ports_file.unlink(missing_ok=True)


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


def _pulse_loop(devices: _Devices, clock: SyncClock, stop: threading.Event) -> int:
    """Emit every device's frames in time order until done or stopped; returns the sync pulses emitted."""
    streams, servo, pulses = devices.streams, devices.servo, 0
    while not stop.is_set():
        live = [name for name, s in streams.items() if not s.done()]
        if not live:
            break
        name = min(live, key=lambda n: streams[n].next_time())
        t = streams[name].next_time()
        if not clock.wait_until(t, stop):
            break
        with servo.lock:
            servo.advance(t)
            emission = streams[name].pop(servo)
            servo.commit(emission.latest)
            send = name != "turntable_data" or servo.sync_output
        if send and not devices.writers[name].put(emission, clock.due(t)):
            break
        if name in devices.synced:
            pulses = max(pulses, emission.tick)
    return pulses


def _stats(devices: _Devices, pulses: int, elapsed: float, stopped: bool) -> EmulatorStats:
    server = devices.server
    return EmulatorStats(pulses, elapsed, stopped, {
        name: DeviceStats(w.frames, dict(w.faults.counts), w.latency.percentile_ms(50), w.latency.percentile_ms(99),
                          w.lost_unread)
        for name, w in devices.writers.items()},
        dict(server.received), server.modes_off, devices.servo.handle(AclCommand(":Mode?", ("ALL",))).text)


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


def spawn_emulator(config: Path, ports_file: Path, speed: str = "max", duration: float | None = None,
                   timeout_s: float = 20.0, stats_file: Path | None = None, log_file: Path | None = None,
                   wait_readers: bool = True, hold: bool = False) -> tuple[subprocess.Popen, dict]:
    """Start ``python -m emulators.emulate`` in its own process; returns it and its ports once open.

    The child runs in its own session, so a Ctrl-C or a hang-up of the terminal reaches only the
    harness, which turns the table off before it stops the devices; it ends with the harness. With
    ``hold`` it keeps its devices up after the pulse train until stopped (see :func:`run_emulator`). Its
    stderr (the stats at the end, any error) goes to ``log_file`` when given. Raises
    :class:`EmulatorError` with the emulator's last line when it exits before opening its ports.
    """
    ports_file.unlink(missing_ok=True)
    if stats_file is not None:
        stats_file.unlink(missing_ok=True)  # its appearance tells that the pulse train has ended
    cmd = [sys.executable, "-m", "emulators.emulate", str(config), "--ports-file", str(ports_file),
           "--speed", speed]
    if duration is not None:
        cmd += ["--duration", str(duration)]
    if stats_file is not None:
        cmd += ["--stats-file", str(stats_file)]
    if wait_readers:
        cmd.append("--wait-readers")
    if hold:
        cmd.append("--hold")
    with open(log_file, "w+b") if log_file is not None else tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
                                preexec_fn=_die_with_parent if sys.platform == "linux" else None)
        deadline = time.monotonic() + timeout_s
        while not ports_file.exists():
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                proc.wait()
                log.seek(0)
                lines = log.read().decode(errors="replace").strip().splitlines()
                raise EmulatorError(lines[-1].removeprefix("emulator: error: ") if lines else
                                    f"the emulator did not open its ports (exit code {proc.returncode})")
            time.sleep(0.02)
    return proc, json.loads(ports_file.read_text())


def stop_emulator(process: subprocess.Popen) -> None:
    """End a spawned emulator: SIGTERM, then SIGKILL if it has not gone within 5 s."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(5.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emulators.emulate", description=__doc__.splitlines()[0])
    parser.add_argument("config", type=Path)
    parser.add_argument("--ports-file", type=Path)
    parser.add_argument("--speed", type=parse_speed, default=1.0, help="multiple of real time, or max")
    parser.add_argument("--duration", type=float, help="s; default trial.duration_s")
    parser.add_argument("--wait-readers", action="store_true", help="start the pulse train once every port has a reader")
    parser.add_argument("--stats-file", type=Path, help="write the run's statistics here as JSON at the end")
    parser.add_argument("--hold", action="store_true",
                        help="after the pulse train, keep the devices (the acl port) up until stopped")
    args = parser.parse_args(argv)
    try:
        stats = run_emulator(load_config(args.config), args.ports_file, args.speed, args.duration,
                             wait_readers=args.wait_readers, stats_file=args.stats_file, hold=args.hold)
    except (ConfigError, OSError) as exc:
        print(f"emulator: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(stats.as_dict()), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
