"""Turntable command client (``acl``): checks limits and interlocks before sending; always ends with Off.

Limits come from :class:`hil.config.LimitsConfig` (ordered outer, middle, inner, as
:data:`hil.samples.GIMBAL_AXES`). A demand outside them raises :class:`LimitError` before a byte is
written. Closing the client, in any way (normal end, an exception, Ctrl-C inside a ``with`` block),
sends ``:Mode ALL,Off`` and reads the modes back.
"""

from __future__ import annotations

import math
from typing import Any

import serial

from drivers.acl import AXIS_NUMBER, AclCodec, AclCommand, AclError, AclReply
from drivers.transport import TransportError, open_serial
from hil.samples import GIMBAL_AXES  # also the index order of LimitsConfig


class LimitError(ValueError):
    """A demand outside the configured turntable limits; nothing was sent."""


class InterlockError(RuntimeError):
    """The table's interlocks are open; the motion command was not sent."""


class TableError(RuntimeError):
    """The table refused a command or did not answer."""


class TableCommandClient:
    """Commands to a turntable over a pyserial URL (``socket://host:9878``, ``rfc2217://host:port``, a serial port)."""

    def __init__(self, url: str, limits: Any, baudrate: int = 115200, timeout_s: float = 2.0) -> None:
        self.url, self.limits, self.baudrate, self.timeout_s = url, limits, baudrate, timeout_s
        self.codec = AclCodec()
        self.port: serial.SerialBase | None = None
        self._position_demand: dict[str, float] = {}

    def open(self, port: serial.SerialBase | None = None) -> TableCommandClient:
        """Open :attr:`url`, or use ``port``: an open port of pyserial's interface (``write``, ``read_until``,
        ``reset_input_buffer``, ``close``), such as the in-process emulated table's."""
        if port is not None:
            self.port = port
            return self
        try:
            self.port = open_serial(self.url, "turntable command port", baudrate=self.baudrate, timeout=self.timeout_s)
        except TransportError as exc:
            raise TableError(str(exc)) from exc
        return self

    def close(self) -> None:
        """Send ``:Mode ALL,Off`` (whatever happened before), read the modes back and release the port;
        raises :class:`TableError` when the table did not confirm that every axis is off."""
        if self.port is None:
            return
        try:
            self.send(AclCommand(":Mode", ("ALL", "Off")))
            modes = self.send(AclCommand(":Mode?", ("ALL",))).text
            if {m.strip().upper() for m in modes.split(",")} != {"O"}:
                raise TableError(f"turntable: after :Mode ALL,Off the axes report modes {modes!r}, not all off")
        finally:
            self.port.close()
            self.port = None

    def __enter__(self) -> TableCommandClient:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def send(self, command: AclCommand) -> AclReply:
        """Send one command and return its reply; raises :class:`TableError` on an error reply or timeout."""
        if self.port is None:
            raise TableError(f"turntable: command port {self.url} is not open")
        line = self.codec.format_command(command)
        try:
            self.port.reset_input_buffer()
            self.port.write(line)
            raw = self.port.read_until(b"\n")
        except (serial.SerialException, OSError) as exc:
            raise TableError(f"turntable: {line.strip().decode()} failed on {self.url}: {exc}") from exc
        if not raw.endswith(b"\n"):
            raise TableError(f"turntable: no reply to {line.strip().decode()} within {self.timeout_s} s")
        try:
            reply = self.codec.parse_reply(raw)
        except AclError as exc:
            raise TableError(f"turntable: unreadable reply {raw!r} to {line.strip().decode()}") from exc
        if not reply.ok:
            raise TableError(f"turntable refused {line.strip().decode()}: ?{reply.error} {reply.text}")
        return reply

    # Queries

    def identify(self) -> str:
        return self.send(AclCommand("*IDN?")).text

    def interlocks_closed(self, gimbal: str) -> bool:
        return self.send(AclCommand(":Interlock?", (_axis(gimbal),))).text.strip().lower() == "closed"

    # Commands

    def apply_limits(self) -> None:
        """Load the configured limits into the table, so it also enforces them (accelerations included)."""
        lim = self.limits
        for k, gimbal in enumerate(GIMBAL_AXES):
            axis = _axis(gimbal)
            self.send(AclCommand(":Limit:Position", (axis, lim.position_min_deg[k], lim.position_max_deg[k])))
            self.send(AclCommand(":Limit:Rate", (axis, lim.rate_dps[k])))
            self.send(AclCommand(":Limit:Acceleration", (axis, lim.accel_dps2[k])))

    def set_mode(self, gimbal: str, mode: str) -> None:
        """Mode Position|Rate|Synthesis|Off; any mode but Off needs the gimbal's interlocks closed."""
        if mode != "Off" and not self.interlocks_closed(gimbal):
            raise InterlockError(f"turntable: interlocks of the {gimbal} axis are open; close them "
                                 f"(:Interlock:Close) before mode {mode}")
        self.send(AclCommand(":Mode", (_axis(gimbal), mode)))

    def demand_position(self, gimbal: str, deg: float) -> None:
        self._check_position(gimbal, deg, deg)
        self.send(AclCommand(":Demand:Position", (_axis(gimbal), deg)))
        self._position_demand[gimbal] = deg

    def demand_rate(self, gimbal: str, dps: float) -> None:
        self._check("rate", gimbal, abs(dps), self.limits.rate_dps, "deg/s")
        self.send(AclCommand(":Demand:Rate", (_axis(gimbal), dps)))

    def demand_oscillator(self, gimbal: str, amplitude_deg: float, frequency_hz: float, phase_deg: float) -> None:
        """Oscillation about the current position demand (Synthesis mode); peak rate and acceleration checked."""
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
        self.send(AclCommand(":Demand:Oscillator", (_axis(gimbal), amplitude_deg, frequency_hz, phase_deg)))

    def configure_sync(self, on: bool) -> None:
        """Start or stop ``tts1`` output on the external sync."""
        self.send(AclCommand(":Configure:Sync", ("ON" if on else "OFF",)))

    def _check_position(self, gimbal: str, low: float, high: float) -> None:
        k = _index(gimbal)
        lo, hi = self.limits.position_min_deg[k], self.limits.position_max_deg[k]
        if not (lo <= low and high <= hi):
            shown = f"{low:g}" if low == high else f"{low:g}..{high:g}"
            raise LimitError(f"turntable: position {shown} deg on the {gimbal} axis is outside the configured "
                             f"limits [{lo:g}, {hi:g}] deg (turntable.limits); nothing was sent")

    def _check(self, what: str, gimbal: str, value: float, limits: tuple, unit: str) -> None:
        limit = limits[_index(gimbal)]
        if not value <= limit:
            raise LimitError(f"turntable: {what} {value:g} {unit} on the {gimbal} axis exceeds the configured "
                             f"limit {limit:g} {unit} (turntable.limits); nothing was sent")


def _index(gimbal: str) -> int:
    if gimbal not in GIMBAL_AXES:
        raise ValueError(f"turntable: unknown axis {gimbal!r}; use one of {', '.join(GIMBAL_AXES)}")
    return GIMBAL_AXES.index(gimbal)


def _axis(gimbal: str) -> str:
    _index(gimbal)
    return AXIS_NUMBER[gimbal]
