"""The pulse-train bench: the emulated IMU and table of one run, driven by one sync pulse train.

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
from emulators.clocks import device_clocks
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
from hil.vocabulary import Port

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


def device_streams(cfg: Config, duration: float) -> tuple[Servo, dict[str, DeviceStream]]:
    """The table's servo and the frame streams (``imu``, ``turntable_data``) of a run of ``duration`` s:
    what the emulated devices send, before any port or fault (frames of a powered-off device marked so)."""
    rate = cfg.imu_rate_hz
    sim = Simulation.from_config(cfg.model_copy(update={"trial": cfg.trial.model_copy(
        update={"duration_s": duration})}))
    imu_cfg = cfg.imu
    imu_clock, table_clock = device_clocks(cfg)
    seed = cfg.trial.seed
    imu_source = ImuSource(imu_clock, seed, imu_codec(imu_cfg, rate), sim.errors, imu_cfg.faults,
                           imu_cfg.errors.turn_on_bias_ug)
    table_source = TableSource(table_clock, seed, np.array(cfg.turntable.zero_offset_arcsec) * ARCSEC)
    streams = {name: DeviceStream(source, sim.truth, source.clock.ticks(duration),
                                  max(1, round(CHUNK_S / source.clock.period)))
               for name, source in ((Port.IMU, imu_source), (Port.TABLE_DATA, table_source))}
    return Servo(cfg.turntable, rate, sim.truth.motion), streams


class Bench:
    """The emulated IMU and table of one run: servo, frame streams, ports, writers, command server."""

    def __init__(self, cfg: Config, duration: float, speed: float | None, stop: threading.Event,
                 wait_readers: bool, link_dir: Path | None = None) -> None:
        """``link_dir``: publish the serial ports as links ``imu`` and ``turntable_data`` there; without
        it only a device configured to unplug gets a link, in a private directory."""
        rate = cfg.imu_rate_hz
        imu_cfg = cfg.imu
        seed = cfg.trial.seed
        self.servo, self.streams = device_streams(cfg, duration)
        codec = self.streams["imu"].source.codec
        self.synced = [n for n, s in self.streams.items() if not s.source.clock.timing.free_running] or ["imu"]
        self.ports: dict = {}
        self.writers: dict[str, DeviceWriter] = {}
        self.server: TableServer | None = None
        self.chamber: EmulatedChamber | None = None
        self.supply: EmulatedSupply | None = None
        unplugging = [f.unplug_at_s is not None for f in (imu_cfg.faults, cfg.turntable.faults)]
        private = any(unplugging) and link_dir is None
        self._links = tempfile.TemporaryDirectory(prefix="hil-emulate-") if private else None

        def pty(name: str, unplugs: bool, responder: Responder | None = None) -> PtyPort:
            link = link_dir / name if link_dir is not None else Path(self._links.name) / name if unplugs else None
            if responder is None:
                return PtyPort(link)
            supply = self.streams["imu"].source.clock.supply  # an unpowered IMU hears nothing
            return CommandedPty(link, responder, lambda: supply is None or supply.on)

        try:
            if link_dir is not None:
                link_dir.mkdir(parents=True, exist_ok=True)
            if codec.link == "can":
                imu_port, imu_damage, imu_baud = CanPort(imu_cfg.can.interface, imu_cfg.can.channel), CanDamage(), None
            else:
                check_baudrate("imu", codec.frame_bytes(), rate, imu_cfg.baudrate)
                imu_port = pty("imu", unplugging[0], responder_for(codec))  # it answers its configuration queries
                imu_damage, imu_baud = ByteDamage(), imu_cfg.baudrate
            self.ports["imu"] = imu_port
            check_baudrate("turntable", TTS1_BYTES, cfg.trial.rate_hz, cfg.turntable.baudrate)  # it sends tts1
            self.ports[Port.TABLE_DATA] = pty(Port.TABLE_DATA, unplugging[1])
            self.server = TableServer(emulated_table(cfg, self.servo, log=True))
            chamber = cfg.environment.chamber
            if chamber is not None and chamber.source == "emulator":
                self.chamber = emulated_chamber(chamber)
                self.streams["imu"].source.state["errors"].follow_chamber(self.chamber.air_at)
            line = self.streams["imu"].source.clock.supply
            if line is not None:  # environment.power.source: emulator
                self.supply = powering(cfg.environment.power, line, self.servo.lock)
            for k, (name, damage, baud, faults) in enumerate((
                    (Port.IMU, imu_damage, imu_baud, imu_cfg.faults),
                    (Port.TABLE_DATA, ByteDamage(), cfg.turntable.baudrate, cfg.turntable.faults))):
                self.writers[name] = DeviceWriter(name, self.ports[name], FaultInjector(faults, damage, seed, k),
                                                  baud, speed, stop, wait_readers)
        except BaseException:
            self.close()
            raise

    def names(self) -> dict:
        """The ports JSON."""
        chamber = {} if self.chamber is None else {"chamber": self.chamber.path}
        power = {} if self.supply is None else {"power": self.supply.resource}
        return {Port.IMU: self.ports[Port.IMU].path, Port.TABLE_DATA: self.ports[Port.TABLE_DATA].path,
                Port.TABLE_CMD: self.server.url, **chamber, **power}

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
