"""The rig: every device a command uses, opened from the config and bound by name, closed on every way out in the
order a lab needs (the table Off first, then the chamber to its ``on_exit``, then the emulated devices stopped).

This is the one module of the harness that builds a transport or opens a device (tests/test_rig.py holds it to
that); the drivers it asks are found by name in :mod:`drivers.registry`. :class:`Rig` holds one live trial's:
``emulator`` (the emulated devices' process, when both sides are emulated, and its ``ports``), ``chamber`` (opened
at its set point before the table moves), ``table`` (the table's :class:`~hil.trial.table_control.TableControl`,
when the harness commands it), and the data streams' transports (:meth:`Rig.links`, :meth:`Rig.table_transport`).
A plan's devices that outlive its trials (the chamber of its soaks, the power supply, the table sent Off at its
end) are opened here too: :func:`open_plan_chamber`, :func:`open_supply`, :func:`table_off`.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from drivers.registry import CHAMBERS, POWER_SUPPLIES
from drivers.scpi_supply import ScpiSupply, SupplyError, SupplySettings
from drivers.table_controller import TableError
from drivers.transport import Transport, open_transport
from emulators.process import EmulatorError, EmulatorRun, spawn_emulator, stop_emulator
from hil.config import Config
from hil.config_environment import ChamberConfig, PowerConfig
from hil.inputs import InputError
from hil.trial.outcome import TrialSetupError
from hil.trial.table_control import TableControl
from hil.vocabulary import DevicePorts, Stream


def emulated(cfg: Config) -> bool:
    """Every device of the config emulated (a mixed config is refused): the table, and the IMU or every unit's."""
    units = cfg.unit_configs() or {"": cfg}
    sources = {cfg.turntable.source, *(unit.imu.source for unit in units.values())}
    if "emulator" in sources and sources != {"emulator"}:
        raise TrialSetupError("imu.source and turntable.source: emulate both devices or neither")
    return sources == {"emulator"}


def command_url(cfg: Config, ports: DevicePorts | None) -> str | None:
    """The table's command port: ``turntable.command_port``, where ``emulator`` means the emulated table's."""
    url = cfg.turntable.command_port
    if url == "emulator":
        if ports is None or ports.table_cmd is None:
            raise TrialSetupError("turntable.command_port: 'emulator' needs turntable.source: emulator")
        return ports.table_cmd
    return url


@dataclass(frozen=True)
class DataLinks:
    """One IMU's trial's data streams: their transports by stream (not yet open: the trial's readers open them) and
    the ports they were found on (the emulator's; None: the config's), which the trial's record names."""

    transports: dict[str, Transport]
    ports: DevicePorts | None

    def recorded_ports(self) -> dict | None:
        """The ports as the trial's record names them (None: the config's)."""
        return None if self.ports is None else self.ports.as_dict()


def data_links(cfg: Config, ports: DevicePorts | None = None, table: Transport | None = None) -> DataLinks:
    """The IMU's and the table's transports of a one-unit config, from the emulator's ``ports`` (ports.json) or from
    the config; ``table``: the table's, already made (shared by several units)."""
    imu_port = ports and ports.imu
    if not imu_port:
        imu_port = cfg.imu.can.port if cfg.imu.source == "can" and cfg.imu.can else cfg.imu.port
    if not imu_port:
        raise TrialSetupError("imu: no port (set imu.port, or imu.source: emulator)")
    imu = open_transport(imu_port, Stream.IMU, cfg.imu.baudrate)
    return DataLinks({Stream.IMU: imu, Stream.TABLE: table or table_transport(cfg, ports)}, ports)


def table_transport(cfg: Config, ports: DevicePorts | None) -> Transport:
    """The table's data transport, from the emulator's ports (ports.json) or from the config."""
    table_port = ports.table_data if ports is not None and ports.table_data else cfg.turntable.data_port
    if not table_port:
        raise TrialSetupError("turntable: no data_port (set turntable.data_port, or turntable.source: emulator)")
    return open_transport(table_port, Stream.TABLE, cfg.turntable.baudrate)


def chamber_controller(cfg: ChamberConfig, emulated_port: str | None = None):
    """The controller of ``environment.chamber``, not yet open: the class its ``controller`` names in
    :data:`drivers.registry.CHAMBERS` on its ``port``, or the emulated chamber's (a Watlow F4) on ``emulated_port``."""
    if cfg.source == "emulator":
        port, cls, options = emulated_port, CHAMBERS.get("watlow-f4"), {}
    else:
        port, cls, options = cfg.port, CHAMBERS.get(cfg.controller), cfg.options
    return cls(port, cls.Options.model_validate(options))


def open_chamber(cfg: ChamberConfig | None, ports: DevicePorts | None):
    """A trial's chamber, open and at ``set_point_c`` (None without a chamber); a chamber that does not answer is a
    :class:`TrialSetupError` naming ``environment.chamber`` and the port."""
    from drivers.watlow_f4 import ChamberError

    if cfg is None:
        return None
    chamber_port = None if ports is None else ports.chamber
    if cfg.source == "emulator" and chamber_port is None:
        raise TrialSetupError("environment.chamber: source: emulator, but the emulator opened no chamber port")
    controller = chamber_controller(cfg, chamber_port)
    try:
        controller.open()
        if cfg.set_point_c is not None:
            controller.set_set_point_c(cfg.set_point_c)
    except ChamberError as exc:
        controller.close()
        raise TrialSetupError(f"environment.chamber: {exc}") from None
    return controller


def open_plan_chamber(cfg: ChamberConfig, start_c: float | None):
    """A plan's chamber, open, and the emulated chamber it talks to (None for a real one), started at ``start_c``
    deg C in this process (its time moved on by the plan)."""
    emulated_chamber = None
    if cfg.source == "emulator":
        from emulators.chamber import emulated_chamber as start

        emulated_chamber = start(cfg.model_copy(update={"set_point_c": start_c}))
    controller = chamber_controller(cfg, emulated_chamber and emulated_chamber.path)
    try:
        return controller.open(), emulated_chamber
    except BaseException:
        if emulated_chamber is not None:
            emulated_chamber.close()
        raise


def release_chamber(controller, cfg: ChamberConfig) -> None:
    """Send the chamber to ``on_exit`` (``hold``: leave its set point) and close it; a failure is a warning."""
    from drivers.watlow_f4 import ChamberError

    try:
        if cfg.on_exit != "hold":
            controller.set_set_point_c(cfg.on_exit)
    except ChamberError as exc:
        print(f"hil: WARNING: could not set the chamber to its on_exit set point: {exc}", file=sys.stderr)
    finally:
        controller.close()


def open_supply(cfg: PowerConfig):
    """The supply of ``environment.power``, open, and the emulated supply serving it (None for a real one); one that
    cannot be reached is bad input naming ``environment.power``. The driver is the class its ``controller`` names in
    :data:`drivers.registry.POWER_SUPPLIES` (``scpi``, or a plug-in of ``turntable_hil.power_supplies``; the
    emulated supply speaks SCPI), given the settings to write."""
    server, resource = None, cfg.port
    if cfg.source == "emulator":
        from emulators.scpi_supply import EmulatedSupply, SupplyState

        server = EmulatedSupply(SupplyState(cfg.load_a, cfg.options.channel or 1))
        resource = server.resource
    options = cfg.options
    cls = POWER_SUPPLIES.get(cfg.controller or "scpi")
    supply: ScpiSupply = cls(resource, SupplySettings(options.voltage_v, options.current_limit_a, options.channel))
    try:
        return supply.open(), server
    except BaseException as exc:  # the connection and the emulated supply closed on every way out, as the chamber's
        supply.close()
        if server is not None:
            server.close()
        if isinstance(exc, SupplyError):
            raise InputError(f"environment.power: {exc}") from None
        raise


def table_off(url: str, turntable) -> str:
    """Every axis of the table on ``url`` Off and the modes read back; what the table said."""
    try:
        control = TableControl(url, turntable).open()
    except TableError as exc:
        return f"not confirmed: {exc}"
    control.stop()
    return f"not confirmed: {control.stop_error}" if control.stop_error else "every axis Off (read back)"


class Rig:
    """The devices of a trial of ``cfg`` (its file ``config_path``) writing to ``out``, emulated ones at ``speed``
    for ``duration`` s; use as a context manager: opened on entry, closed on every way out."""

    def __init__(self, cfg: Config, config_path: Path, out: Path, speed: str, duration: float | None) -> None:
        self.cfg, self.config_path, self.out, self.speed, self.duration = cfg, config_path, out, speed, duration
        self.emulator = None
        self.ports: DevicePorts | None = None
        self.chamber = None
        self.table: TableControl | None = None

    def __enter__(self) -> Rig:
        try:
            if emulated(self.cfg):
                try:
                    run = EmulatorRun(self.speed, self.duration, wait_readers=True, hold=True,
                                      stats_file=self.out / "emulator.json")
                    self.emulator, ports = spawn_emulator(self.config_path, self.out / "ports.json", run,
                                                          log_file=self.out / "emulator.log")
                    self.ports = DevicePorts.of(ports)
                except EmulatorError as exc:
                    raise TrialSetupError(f"{self.config_path}: {exc}") from None
            self.chamber = open_chamber(self.cfg.environment.chamber, self.ports)  # before the table moves
            url = command_url(self.cfg, self.ports)
            if url is not None:
                self.table = TableControl(url, self.cfg.turntable)
                self.table.open()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def links(self) -> DataLinks:
        """The data streams of this one-unit trial."""
        return data_links(self.cfg, self.ports)

    def unit_links(self, name: str, unit: Config, table: Transport) -> DataLinks:
        """The data streams of the unit ``name`` (its one-unit config ``unit``), on the shared table's ``table``."""
        return data_links(unit, None if self.ports is None else self.ports.unit(name), table)

    def table_transport(self) -> Transport:
        """The table's data transport, for a reader the units share."""
        return table_transport(self.cfg, self.ports)

    def source_done(self) -> bool:
        """True once the emulated devices' run has ended (their process gone, or its statistics written)."""
        return self.emulator is not None and (self.emulator.poll() is not None
                                              or (self.out / "emulator.json").exists())

    def close(self) -> None:
        """The table Off (a warning when that cannot be confirmed), the chamber to its ``on_exit``, the emulated
        devices stopped."""
        if self.table is not None:
            self.table.stop()
            if self.table.stop_error:
                print(f"hil: WARNING: could not confirm the turntable is off: {self.table.stop_error}", file=sys.stderr)
        if self.chamber is not None:  # after the table is off
            release_chamber(self.chamber, self.cfg.environment.chamber)
            self.chamber = None
        if self.emulator is not None:
            stop_emulator(self.emulator)
