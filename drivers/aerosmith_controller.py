"""An Ideal Aerosmith single-axis rate table as a :class:`~drivers.table_controller.TableController`.

The command set is the one the public client actigraph/RateTableSweepGUI (``RateSweepGUI.py``) uses:
three letters and a number, ended by CR LF (``VEL30``, ``ACL50``, ``MOV12.5``, ``JOG-10``, ``AMP5``,
``FRQ0.25``, ``CYC0``, ``SGO``, ``STO``, ``PPO``, ``PVE``, ``STA``). A command answers a reply line and then a
prompt line; ``JOG``, ``SGO`` and ``STO`` answer nothing (the client reads on at its next command), and
``STO`` acts without its line end. Where the public client shows no more, these are our readings: the
prompt is ``>``, a refused command answers ``ERR <text>``, and ``STA`` is an integer whose bits 0-1 say
the mode (0 stopped, 1 position, 2 rate, 3 sinusoid), bit 2 the drive enabled (the interlocks closed,
which the operator does at the table; there is no command), bit 3 a latched fault, bit 4 moving.

The table turns one gimbal of the harness's geometry (``controller_options.axis``, the outer axis by
default); the others stay where they are. Its position limits are the harness's to check; ``VEL`` sets
the rate of position moves and ``ACL`` the acceleration of every motion.
"""

from __future__ import annotations

from typing import ClassVar, Literal

import serial

from drivers.table_controller import NoOptions, TableController, TableError
from hil.samples import GIMBAL_AXES
from hil.vocabulary import TableMode

PROMPT = ">"
SILENT = ("JOG", "SGO", "STO")  # commands that answer nothing
STA_MODES = (TableMode.OFF, TableMode.POSITION, TableMode.RATE, TableMode.SYNTHESIS)
STA_ENABLED, STA_FAULT, STA_MOVING = 4, 8, 16


class AerosmithOptions(NoOptions):
    """``turntable.controller_options`` of the Ideal Aerosmith table."""

    axis: Literal["outer", "middle", "inner"] = "outer"


class AerosmithController(TableController):
    """A single-axis Ideal Aerosmith rate table (module docstring)."""

    name: ClassVar[str] = "aerosmith"
    Options: ClassVar[type] = AerosmithOptions
    emulated: ClassVar[str] = "emulators.aerosmith_table:AerosmithTable"
    baudrate: ClassVar[int] = 9600

    @property
    def gimbals(self) -> tuple[str, ...]:  # type: ignore[override]
        return (self.options.axis,)

    @classmethod
    def refusal(cls, modes: set[str], gimbals: set[str], options: AerosmithOptions | None = None) -> str | None:
        axis = (options or AerosmithOptions()).axis
        others = ", ".join(g for g in GIMBAL_AXES if g in gimbals and g != axis)
        if others:
            return (f"turntable.controller 'aerosmith' turns one axis ({axis}, controller_options.axis); the trial "
                    f"moves the {others} axis too")
        return None

    def request(self, command: str) -> str:
        """Send one command; its reply line (empty for the silent ones). Raises :class:`TableError` on ``ERR``."""
        port = self._io(command)
        try:
            port.reset_input_buffer()
            port.write(command.encode("ascii") + b"\r\n")
            if command[:3] in SILENT:
                return ""
            reply = port.read_until(b"\n").decode("ascii", "replace").strip()
            prompt = port.read_until(b"\n").decode("ascii", "replace").strip()
        except (serial.SerialException, OSError) as exc:
            raise TableError(f"turntable: {command} failed on {self.url}: {exc}") from exc
        if prompt != PROMPT:
            raise TableError(f"turntable: no reply and prompt to {command} within {self.timeout_s} s "
                             f"(got {reply!r}, {prompt!r})")
        if reply.startswith("ERR"):
            raise TableError(f"turntable refused {command}: {reply}")
        return reply

    def status(self) -> int:
        return int(self.request("STA"))

    def identify(self) -> str:
        return f"Ideal Aerosmith rate table, status {self.status()}"

    def read_position(self, gimbal: str) -> float:
        self._gimbal(gimbal)
        return float(self.request("PPO"))

    def _load_limits(self, gimbal: str, low: float, high: float, rate: float, accel: float) -> None:
        self.request(f"VEL{rate:g}")
        self.request(f"ACL{accel:g}")

    def _interlocks(self, gimbal: str) -> str:
        status = self.status()
        return "fault" if status & STA_FAULT else "closed" if status & STA_ENABLED else "open"

    def _close_interlocks(self, gimbal: str) -> None:
        raise TableError("turntable: the Ideal Aerosmith table's drive is enabled at the table; it has no command")

    def _mode(self, gimbal: str, mode: str) -> None:
        """The table's motion commands carry their mode: Off stops; the others take effect with the demand."""
        if mode == TableMode.OFF:
            self.request("STO")

    def _position(self, gimbal: str, deg: float) -> None:
        self.request(f"MOV{deg:.6f}")

    def _rate(self, gimbal: str, dps: float) -> None:
        self.request(f"JOG{dps:.6f}")

    def _oscillator(self, gimbal: str, amplitude_deg: float, frequency_hz: float, phase_deg: float) -> None:
        if phase_deg:
            raise TableError("turntable: the Ideal Aerosmith sinusoid starts at phase 0; set the phase to 0")
        for command in (f"AMP{amplitude_deg:.6f}", f"FRQ{frequency_hz:.6f}", "CYC0", "SGO"):
            self.request(command)

    def _off(self) -> dict[str, str]:
        self.request("STO")
        return {self.options.axis: STA_MODES[self.status() & 3]}
