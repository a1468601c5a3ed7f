"""The rig of one live trial command: its devices, opened once from the config and bound by name, closed on every
way out in the order a lab needs (the table Off first, then the chamber to its ``on_exit``, then the emulated devices
stopped).

``emulator`` (the emulated devices' process, when both sides are emulated, and its ``ports``), ``chamber`` (opened at
its set point before the table moves) and ``table`` (the table's :class:`~hil.trial.table_control.TableControl`, when
the harness commands it); a runner takes what it uses and binds the rest of the trial to them.
"""

from __future__ import annotations

import sys
from pathlib import Path

from emulators.process import EmulatorError, spawn_emulator, stop_emulator
from hil.config import Config
from hil.trial.chamber import open_chamber, release_chamber
from hil.trial.outcome import TrialSetupError
from hil.trial.table_control import TableControl
from hil.vocabulary import Port


def emulated(cfg: Config) -> bool:
    """Every device of the config emulated (a mixed config is refused): the table, and the IMU or every unit's."""
    units = cfg.unit_configs() or {"": cfg}
    sources = {cfg.turntable.source, *(unit.imu.source for unit in units.values())}
    if "emulator" in sources and sources != {"emulator"}:
        raise TrialSetupError("imu.source and turntable.source: emulate both devices or neither")
    return sources == {"emulator"}


def command_url(cfg: Config, ports: dict | None) -> str | None:
    """The table's command port: ``turntable.command_port``, where ``emulator`` means the emulated table's."""
    url = cfg.turntable.command_port
    if url == "emulator":
        if ports is None or Port.TABLE_CMD not in ports:
            raise TrialSetupError("turntable.command_port: 'emulator' needs turntable.source: emulator")
        return ports[Port.TABLE_CMD]
    return url


class Rig:
    """The devices of a trial of ``cfg`` (its file ``config_path``) writing to ``out``, emulated ones at ``speed``
    for ``duration`` s; use as a context manager: opened on entry, closed on every way out."""

    def __init__(self, cfg: Config, config_path: Path, out: Path, speed: str, duration: float | None) -> None:
        self.cfg, self.config_path, self.out, self.speed, self.duration = cfg, config_path, out, speed, duration
        self.emulator = None
        self.ports: dict | None = None
        self.chamber = None
        self.table: TableControl | None = None

    def __enter__(self) -> Rig:
        try:
            if emulated(self.cfg):
                try:
                    self.emulator, self.ports = spawn_emulator(
                        self.config_path, self.out / "ports.json", self.speed, self.duration,
                        stats_file=self.out / "emulator.json", log_file=self.out / "emulator.log", hold=True)
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
