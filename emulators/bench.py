"""The pulse-train bench: the emulated IMUs and table of one run, driven by one sync pulse train.

:class:`Bench` assembles the devices from the config (servo, frame streams of :mod:`emulators.sources`,
ports of :mod:`emulators.ports`, writers of :mod:`emulators.paced_writer`, the emulated table's command server);
:meth:`Bench.pulse_loop` emits every device's frames in time order, paced by a :class:`SyncClock`;
:meth:`Bench.stats` sums the run up as :class:`EmulatorStats`. :mod:`emulators.process` runs it.
"""

from __future__ import annotations

import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from drivers.codec import check_baudrate
from drivers.tts1 import FRAME_SIZE as TTS1_BYTES
from drivers.registry import imu_codec
from emulators.chamber import EmulatedChamber, emulated_chamber
from emulators.clocks import PowerLine, device_clocks
from emulators.faults import ByteDamage, CanDamage, FaultInjector
from emulators.imu_commands import CommandedPty, Responder, responder_for
from emulators.ports import CanPort, PtyPort
from emulators.servo import Servo
from emulators.simulation import Simulation
from emulators.sources import DeviceStream, ImuSource, TableSource
from emulators.table_server import TableServer, emulated_table
from emulators.paced_writer import DeviceWriter
from emulators.scpi_supply import EmulatedSupply, powering
from hil.config import Config
from hil.units import ARCSEC
from hil.vocabulary import UNIT_PREFIX, DevicePorts, Port

CHUNK_S = 0.25  # frames computed ahead, trial seconds


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
    table_commands: dict[str, int] = field(default_factory=dict)  # commands received, by header
    table_modes_off: int = 0  # Offs of every axis the table accepted
    table_modes: str = ""  # the table's modes at the end, in its own words (Acutrol: axis 1 first)
    started: float | None = None  # time.monotonic() of trial time 0 when paced: trial time t was due at started + t / speed
    table_log: list[tuple[str, int]] = field(default_factory=list)  # every command message and its error code

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


def emulated_imus(cfg: Config) -> dict[str, Config]:
    """The emulated IMUs of a config by their device name: ``imu``, or ``imu.<name>`` for each of its ``units``
    (:data:`UNIT_PREFIX`), each with its one-unit config (:meth:`hil.config.Config.unit_configs`)."""
    return {f"{UNIT_PREFIX}{name}": unit for name, unit in cfg.unit_configs().items()} or {Port.IMU: cfg}


def device_streams(cfg: Config, duration: float) -> tuple[Servo, dict[str, DeviceStream]]:
    """The table's servo and the frame streams (each IMU's, ``turntable_data``) of a run of ``duration`` s:
    what the emulated devices send, before any port or fault (frames of a powered-off device marked so). Every
    IMU senses the one table motion through its own mounting, with its own errors, seed and counter start."""
    sim = _simulation(cfg, duration)
    imus = emulated_imus(cfg)
    rate = max(unit.imu_rate_hz for unit in imus.values())  # the sync pulse train's: the units share one rate
    _, table_clock = device_clocks(cfg.model_copy(update={"imu": cfg.imu.model_copy(update={"rate_hz": rate})}))
    streams = {name: _imu_stream(unit, duration, sim if unit is cfg else None) for name, unit in imus.items()}
    table_source = TableSource(table_clock, cfg.trial.seed, np.array(cfg.turntable.zero_offset_arcsec) * ARCSEC)
    streams[Port.TABLE_DATA] = DeviceStream(table_source, sim.truth, table_clock.ticks(duration),
                                            max(1, round(CHUNK_S / table_clock.period)))
    return Servo(cfg.turntable, rate, sim.truth.motion), streams


def _simulation(cfg: Config, duration: float) -> Simulation:
    return Simulation.from_config(cfg.model_copy(update={"trial": cfg.trial.model_copy(
        update={"duration_s": duration})}))


def _imu_stream(cfg: Config, duration: float, sim: Simulation | None) -> DeviceStream:
    """The frames of the IMU of the one-unit ``cfg``: its errors and truth those of ``sim`` (None: its own)."""
    sim = sim or _simulation(cfg, duration)
    clock, _ = device_clocks(cfg)
    imu = cfg.imu
    source = ImuSource(clock, cfg.trial.seed, imu_codec(imu, cfg.imu_rate_hz), sim.errors, imu.faults,
                       imu.errors.turn_on_bias_ug)
    return DeviceStream(source, sim.truth, clock.ticks(duration), max(1, round(CHUNK_S / clock.period)))


class Bench:
    """The emulated IMUs and table of one run: servo, frame streams, ports, writers, command server."""

    def __init__(self, cfg: Config, duration: float, speed: float | None, stop: threading.Event,
                 wait_readers: bool, link_dir: Path | None = None) -> None:
        """``link_dir``: publish the serial ports as links ``imu`` (``imu.<name>`` for each unit) and
        ``turntable_data`` there; without it only a device configured to unplug gets a link, in a private
        directory."""
        self.imus = emulated_imus(cfg)
        self.servo, self.streams = device_streams(cfg, duration)
        self.synced = [n for n, s in self.streams.items() if not s.source.clock.timing.free_running] or list(self.imus)
        self.ports: dict = {}
        self.writers: dict[str, DeviceWriter] = {}
        self.server: TableServer | None = None
        self.chamber: EmulatedChamber | None = None
        self.supply: EmulatedSupply | None = None
        unplugging = [unit.imu.faults.unplug_at_s is not None for unit in self.imus.values()]
        private = (any(unplugging) or cfg.turntable.faults.unplug_at_s is not None) and link_dir is None
        self._links = tempfile.TemporaryDirectory(prefix="hil-emulate-") if private else None
        self._link_dir = link_dir
        try:
            if link_dir is not None:
                link_dir.mkdir(parents=True, exist_ok=True)
            for k, (name, unit) in enumerate(self.imus.items()):
                self._open_imu(name, unit, speed, stop, wait_readers, unplugging[k])
            check_baudrate("turntable", TTS1_BYTES, cfg.trial.rate_hz, cfg.turntable.baudrate)  # it sends tts1
            table_faults = cfg.turntable.faults
            self.ports[Port.TABLE_DATA] = self._pty(Port.TABLE_DATA, table_faults.unplug_at_s is not None)
            self.writers[Port.TABLE_DATA] = DeviceWriter(
                Port.TABLE_DATA, self.ports[Port.TABLE_DATA], FaultInjector(table_faults, ByteDamage(),
                                                                            cfg.trial.seed, 1),
                cfg.turntable.baudrate, speed, stop, wait_readers)
            self.server = TableServer(emulated_table(cfg, self.servo, log=True))
            self._open_environment(cfg)
        except BaseException:
            self.close()
            raise

    def _pty(self, name: str, unplugs: bool, responder: Responder | None = None,
             supply: PowerLine | None = None) -> PtyPort:
        """A serial device's port, published as a link where asked or where it unplugs; one with a ``responder``
        answers its configuration queries while its ``supply`` powers it."""
        links = self._link_dir or (Path(self._links.name) if unplugs else None)
        link = links / name if links is not None else None
        if responder is None:
            return PtyPort(link)
        return CommandedPty(link, responder, lambda: supply is None or supply.on)

    def _open_imu(self, name: str, unit: Config, speed: float | None, stop: threading.Event, wait_readers: bool,
                  unplugs: bool) -> None:
        """The port and writer of the IMU ``name`` of the one-unit config ``unit``."""
        imu, source = unit.imu, self.streams[name].source
        if source.codec.link == "can":
            port, damage, baud = CanPort(imu.can.interface, imu.can.channel), CanDamage(), None
        else:
            check_baudrate(name, source.codec.frame_bytes(), unit.imu_rate_hz, imu.baudrate)
            port = self._pty(name, unplugs, responder_for(source.codec), source.clock.supply)
            damage, baud = ByteDamage(), imu.baudrate
        self.ports[name] = port
        self.writers[name] = DeviceWriter(name, port, FaultInjector(imu.faults, damage, unit.trial.seed, 0), baud,
                                          speed, stop, wait_readers)

    def _open_environment(self, cfg: Config) -> None:
        """The emulated chamber (every IMU's temperature follows its air) and supply (powering every IMU)."""
        sources = [self.streams[name].source for name in self.imus]
        chamber = cfg.environment.chamber
        if chamber is not None and chamber.source == "emulator":
            self.chamber = emulated_chamber(chamber)
            for source in sources:
                source.state["errors"].follow_chamber(self.chamber.air_at)
        lines = [source.clock.supply for source in sources if source.clock.supply is not None]
        if lines:  # environment.power.source: emulator
            self.supply = powering(cfg.environment.power, lines, self.servo.lock)

    def names(self) -> dict:
        """The ports JSON: ``imu``, or ``units: {<name>: {imu: ...}}``, and the table's and environment's."""
        imus = {name: self.ports[name].path for name in self.imus}
        units = {} if Port.IMU in imus else {name.removeprefix(UNIT_PREFIX): path for name, path in imus.items()}
        return DevicePorts(imus.get(Port.IMU), self.ports[Port.TABLE_DATA].path, self.server.url,
                           None if self.chamber is None else self.chamber.path,
                           None if self.supply is None else self.supply.resource, units).as_dict()

    def close(self) -> None:
        if self.server is not None:
            self.server.close()
        if self.chamber is not None:
            self.chamber.close()
        if self.supply is not None:
            self.supply.close()
        for port in self.ports.values():
            port.close()
        if self._links is not None:
            self._links.cleanup()

    def ptys(self) -> list[PtyPort]:
        """The serial ports (a reader opens them; a CAN bus has no reader to wait for)."""
        return [p for p in self.ports.values() if isinstance(p, PtyPort)]

    def pulse_loop(self, clock: SyncClock, stop: threading.Event) -> int:
        """Emit every device's frames in time order until done or stopped; returns the sync pulses emitted."""
        streams, servo, pulses = self.streams, self.servo, 0
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
                send = name != Port.TABLE_DATA or servo.sync_output
            if send and not self.writers[name].put(emission, clock.due(t)):
                break
            if name in self.synced:
                pulses = max(pulses, emission.tick)
        return pulses

    def stats(self, pulses: int, elapsed: float, stopped: bool, started: float | None = None) -> EmulatorStats:
        """The run so far: ``pulses`` emitted in ``elapsed`` s, whether it was ``stopped`` early, and when its
        paced clock ``started`` (monotonic)."""
        commands = self.server.responder
        return EmulatorStats(pulses, elapsed, stopped, {
            name: DeviceStats(w.frames, dict(w.faults.counts), w.latency.percentile_ms(50),
                              w.latency.percentile_ms(99), w.lost_unread)
            for name, w in self.writers.items()},
            dict(commands.received), commands.offs, commands.modes(),
            started, list(commands.log))
