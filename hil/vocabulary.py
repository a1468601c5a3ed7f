"""The harness's words, each vocabulary one enum: what the code compares and writes is a member, never a literal
(``tests/test_registry.py`` looks for the old literals outside this module). Members are ``str`` and equal to
their values, so files, messages and ports.json read as before."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any


class TableMode(StrEnum):
    """A table axis's servo mode: the controllers' and the emulated servo's one alphabet."""

    POSITION = "position"
    RATE = "rate"
    SYNTHESIS = "synthesis"  # an oscillator about the centre position
    OFF = "off"


class Port(StrEnum):
    """The devices' ports, as ports.json and the emulator name them."""

    IMU = "imu"
    TABLE_DATA = "turntable_data"
    TABLE_CMD = "turntable_cmd"
    UNITS = "units"  # ports.json of a units config: {"units": {<name>: {"imu": ...}}}
    CHAMBER = "chamber"  # the emulated chamber's pty, with environment.chamber
    POWER = "power"  # the emulated supply's VISA resource, with environment.power


@dataclass(frozen=True)
class DevicePorts:
    """Where the devices are, as ports.json names them (docs/emulator.md): each a pyserial URL or device path, a CAN
    bus (``{"interface", "channel"}``) or a VISA resource; a units config's IMUs by unit name (``units``) instead of
    ``imu``. A device absent is None (not written)."""

    imu: Any = None
    table_data: str | None = None
    table_cmd: str | None = None
    chamber: str | None = None
    power: str | None = None
    units: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of(cls, doc: dict[str, Any]) -> DevicePorts:
        """The ports of a ports.json document."""
        units = {name: ports[Port.IMU] for name, ports in doc.get(Port.UNITS, {}).items()}
        return cls(doc.get(Port.IMU), doc.get(Port.TABLE_DATA), doc.get(Port.TABLE_CMD), doc.get(Port.CHAMBER),
                   doc.get(Port.POWER), units)

    def unit(self, name: str) -> DevicePorts:
        """The ports of the unit ``name``'s trial: its IMU's and the table's data port, which the units share."""
        return DevicePorts(self.units[name], self.table_data)

    def as_dict(self) -> dict[str, Any]:
        """The ports.json document (a trial's ``record.ports``), in its order, without the devices absent."""
        doc: dict[str, Any] = {} if self.imu is None else {Port.IMU.value: self.imu}
        if self.units:
            doc[Port.UNITS.value] = {name: {Port.IMU.value: port} for name, port in self.units.items()}
        for key, value in ((Port.TABLE_DATA, self.table_data), (Port.TABLE_CMD, self.table_cmd),
                           (Port.CHAMBER, self.chamber), (Port.POWER, self.power)):
            if value is not None:
                doc[key.value] = value
        return doc


UNIT_PREFIX = "imu."  # the emulator's device name of a unit's IMU: imu.<name>


class Stream(StrEnum):
    """The streams a trial records and decodes."""

    IMU = "imu"
    TABLE = "table"


class PairedBy(StrEnum):
    """What confirmed the sync pairing (result.json ``streams.sync.paired_by``)."""

    RECEIVE_TIME = "receive_time"
    MOTION = "motion"


class CalibrationPhase(StrEnum):
    """Where a calibration step is: not started, moving to its angles, ramping to its rates, in its window."""

    IDLE = ""
    MOVING = "moving"
    RAMPING = "ramping"
    WINDOW = "window"


class StreamEventKind(StrEnum):
    """What happened to a stream's transport (:class:`drivers.codec.StreamEvent`)."""

    OUTAGE = "outage"
    RECONNECTED = "reconnected"


class TrialKind(StrEnum):
    """What a history row files: a trial's kind (docs/history.md)."""

    SWING = "swing"
    CALIBRATION = "calibration"
    NOISE = "noise"


class Verdict(StrEnum):
    """A judged measurement's, and a completed trial's, verdict."""

    PASS = "PASS"
    FAIL = "FAIL"
