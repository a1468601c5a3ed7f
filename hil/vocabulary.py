"""The harness's words, each vocabulary one enum: what the code compares and writes is a member, never a literal
(``tests/test_registry.py`` looks for the old literals outside this module). Members are ``str`` and equal to
their values, so files, messages and ports.json read as before."""

from __future__ import annotations

from enum import StrEnum


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
