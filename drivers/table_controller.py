"""The turntable controller interface: what a trial asks of a table, whatever its command language.

A controller (one module per dialect, found by name in :mod:`drivers.controllers`) implements the
primitives (``_``-prefixed methods) on an open port; this class checks every demand against
``turntable.limits`` before a byte is written (:class:`LimitError`), refuses a servo mode while an
axis' interlocks are open (:class:`InterlockError`), and turns every axis Off when closed, in any way
(normal end, an exception, Ctrl-C inside a ``with`` block), reading the modes back. Limits are ordered
outer, middle, inner (:data:`hil.samples.GIMBAL_AXES`); modes are ``position``, ``rate``, ``synthesis``
(an oscillation about the position demand) and ``off``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import serial
from pydantic import BaseModel, ConfigDict

from drivers.transport import TransportError, open_serial
from hil.samples import GIMBAL_AXES  # also the index order of LimitsConfig
from hil.vocabulary import TableMode

MODES = tuple(TableMode)
MOTION_MODES = {"swing": TableMode.SYNTHESIS, "rate": TableMode.RATE, "positions": TableMode.POSITION,
                "static": TableMode.POSITION}
"""The mode that performs each ``turntable.motion.kind``: a swing oscillates about the centre, a rate
table turns at its demand, static and positions hold position demands."""


class LimitError(ValueError):
    """A demand outside the configured turntable limits; nothing was sent."""


class InterlockError(RuntimeError):
    """The table's interlocks are open; the motion command was not sent."""


class TableError(RuntimeError):
    """The table refused a command, did not answer, or cannot do what was asked."""


class NoOptions(BaseModel):
    """A controller without options."""

    model_config = ConfigDict(extra="forbid")


class TableController(ABC):
    """Commands to a turntable over a pyserial URL (``socket://host:port``, ``rfc2217://``, a serial port).

    Class attributes say what the controller can do: :attr:`gimbals` it commands, :attr:`modes` it has,
    :attr:`sync_command` whether it turns the sync output on and off by command.
    """

    name: ClassVar[str] = ""
    Options: ClassVar[type[BaseModel]] = NoOptions
    emulated: ClassVar[str] = ""  # "module:Class" of its emulated table (drivers.registry.Registry.emulated)
    gimbals: ClassVar[tuple[str, ...]] = GIMBAL_AXES
    modes: ClassVar[frozenset[str]] = frozenset(MODES)
    sync_command: ClassVar[bool] = False
    baudrate: ClassVar[int] = 115200

    def __init__(self, url: str, limits: Any, options: BaseModel | None = None, baudrate: int | None = None,
                 timeout_s: float = 2.0) -> None:
        self.url, self.limits, self.timeout_s = url, limits, timeout_s
        self.options = options if options is not None else self.Options()
        self.link_baudrate = baudrate or self.baudrate
        self.port: serial.SerialBase | None = None
        self._position_demand: dict[str, float] = {}

    # Port

    def open(self, port: Any = None) -> TableController:
        """Open :attr:`url`, or use ``port``: an open port of pyserial's interface (``write``, ``read``,
        ``read_until``, ``reset_input_buffer``, ``close``), such as an in-process emulated table's."""
        if port is not None:
            self.port = port
            return self
        try:
            self.port = open_serial(self.url, "turntable command port", baudrate=self.link_baudrate,
                                    timeout=self.timeout_s)
        except TransportError as exc:
            raise TableError(str(exc)) from exc
        return self

    def close(self) -> None:
        """Every axis Off (whatever happened before), the modes read back, the port released; raises
        :class:`TableError` when the table did not confirm that every axis is off."""
        if self.port is None:
            return
        try:
            self.off()
        finally:
            self.port.close()
            self.port = None

    def __enter__(self) -> TableController:
        return self if self.port is not None else self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _io(self, what: str) -> serial.SerialBase:
        if self.port is None:
            raise TableError(f"turntable: command port {self.url} is not open ({what})")
        return self.port

    # What a trial may ask

    @classmethod
    def refusal(cls, modes: set[str], gimbals: set[str], options: BaseModel | None = None) -> str | None:
        """Why this controller (with ``options``) cannot run a trial that needs ``modes`` on ``gimbals``
        (None: it can)."""
        missing = [g for g in GIMBAL_AXES if g in gimbals and g not in cls.gimbals]
        if missing:
            return (f"turntable.controller {cls.name!r} commands the {', '.join(cls.gimbals)} axis only; the trial "
                    f"moves the {', '.join(missing)} axis too")
        lacking = sorted(set(modes) - cls.modes)
        if lacking:
            return f"turntable.controller {cls.name!r} has no {', '.join(lacking)} mode, which the trial needs"
        return None

    # Commands, checked

    def apply_limits(self) -> None:
        """Load the configured limits into the table, so it also enforces them."""
        for gimbal in self.gimbals:
            self._load_limits(gimbal, *self._limits_of(gimbal))

    def interlocks_closed(self, gimbal: str) -> bool:
        return self._interlocks(self._gimbal(gimbal)) == "closed"

    def close_interlocks(self, gimbal: str) -> None:
        self._close_interlocks(self._gimbal(gimbal))

    def set_mode(self, gimbal: str, mode: str) -> None:
        """Mode position|rate|synthesis|off; any but off needs the gimbal's interlocks closed."""
        if mode not in self.modes:
            raise TableError(f"turntable.controller {self.name!r} has no {mode} mode")
        if mode != TableMode.OFF and not self.interlocks_closed(gimbal):
            raise InterlockError(f"turntable: interlocks of the {gimbal} axis are open; close them before mode {mode}")
        self._mode(gimbal, mode)

    def demand_position(self, gimbal: str, deg: float) -> None:
        self._check_position(self._gimbal(gimbal), deg, deg)
        self._position(gimbal, deg)
        self._position_demand[gimbal] = deg

    def demand_rate(self, gimbal: str, dps: float) -> None:
        self._check("rate", self._gimbal(gimbal), abs(dps), self.limits.rate_dps, "deg/s")
        self._rate(gimbal, dps)

    def demand_oscillator(self, gimbal: str, amplitude_deg: float, frequency_hz: float, phase_deg: float) -> None:
        """Oscillation about the current position demand; its excursion, peak rate and acceleration checked."""
        self._gimbal(gimbal)
        if amplitude_deg < 0 or frequency_hz < 0:
            raise LimitError(f"turntable: oscillator amplitude and frequency must be >= 0, got "
                             f"{amplitude_deg} deg, {frequency_hz} Hz")
        if gimbal not in self._position_demand:
            raise LimitError(f"turntable: demand a position on the {gimbal} axis before an oscillation, "
                             "so its excursion can be checked against the position limits")
        center = self._position_demand[gimbal]
        self._check_position(gimbal, center - amplitude_deg, center + amplitude_deg)
        omega = 2.0 * math.pi * frequency_hz
        self._check("peak rate", gimbal, omega * amplitude_deg, self.limits.rate_dps, "deg/s")
        self._check("peak acceleration", gimbal, omega * omega * amplitude_deg, self.limits.accel_dps2, "deg/s^2")
        self._oscillator(gimbal, amplitude_deg, frequency_hz, phase_deg)

    def sync_output(self, on: bool) -> bool:
        """Turn the sync output on or off where the controller has a command for it; False where it has
        none (set at the controller's console; the data port shows whether frames come)."""
        if self.sync_command:
            self._sync(on)
        return self.sync_command

    def off(self) -> None:
        """Every commanded axis Off, then the modes read back; raises :class:`TableError` unless all are off."""
        modes = self._off()
        if any(mode != TableMode.OFF for mode in modes.values()):
            raise TableError(f"turntable: after Off the axes report modes "
                             f"{', '.join(f'{g} {m}' for g, m in modes.items())}, not all off")

    # Primitives of a dialect

    @abstractmethod
    def identify(self) -> str:
        ...

    @abstractmethod
    def read_position(self, gimbal: str) -> float:
        """The gimbal's reported position, deg."""
        ...

    @abstractmethod
    def _load_limits(self, gimbal: str, low: float, high: float, rate: float, accel: float) -> None:
        ...

    @abstractmethod
    def _interlocks(self, gimbal: str) -> str:
        """``closed``, ``open`` or ``fault``."""
        ...

    @abstractmethod
    def _close_interlocks(self, gimbal: str) -> None:
        ...

    @abstractmethod
    def _mode(self, gimbal: str, mode: str) -> None:
        ...

    @abstractmethod
    def _position(self, gimbal: str, deg: float) -> None:
        ...

    @abstractmethod
    def _rate(self, gimbal: str, dps: float) -> None:
        ...

    @abstractmethod
    def _oscillator(self, gimbal: str, amplitude_deg: float, frequency_hz: float, phase_deg: float) -> None:
        ...

    def _sync(self, on: bool) -> None:
        raise TableError(f"turntable.controller {self.name!r} has no sync output command")

    @abstractmethod
    def _off(self) -> dict[str, str]:
        """Every commanded axis Off; the modes read back, by gimbal."""
        ...

    # Checks

    def _gimbal(self, gimbal: str) -> str:
        if gimbal not in self.gimbals:
            raise TableError(f"turntable: the {self.name} controller does not command the {gimbal!r} axis "
                             f"(it commands {', '.join(self.gimbals)})")
        return gimbal

    def _limits_of(self, gimbal: str) -> tuple[float, float, float, float]:
        k, lim = GIMBAL_AXES.index(gimbal), self.limits
        return lim.position_min_deg[k], lim.position_max_deg[k], lim.rate_dps[k], lim.accel_dps2[k]

    def _check_position(self, gimbal: str, low: float, high: float) -> None:
        lo, hi, _, _ = self._limits_of(gimbal)
        if not (lo <= low and high <= hi):
            shown = f"{low:g}" if low == high else f"{low:g}..{high:g}"
            raise LimitError(f"turntable: position {shown} deg on the {gimbal} axis is outside the configured "
                             f"limits [{lo:g}, {hi:g}] deg (turntable.limits); nothing was sent")

    def _check(self, what: str, gimbal: str, value: float, limits: tuple, unit: str) -> None:
        limit = limits[GIMBAL_AXES.index(gimbal)]
        if not value <= limit:
            raise LimitError(f"turntable: {what} {value:g} {unit} on the {gimbal} axis exceeds the configured "
                             f"limit {limit:g} {unit} (turntable.limits); nothing was sent")
