"""The Acutrol3000 as a :class:`~drivers.table_controller.TableController`, in the language of :mod:`drivers.acl`.

Axes 1 inner, 2 middle, 3 outer. Limits go to the Position, Rate and Synthesis profilers
(``:Limit:Lowposition <mode>,<axis>,<value>;Highposition ...;Rate ...;Acceleration ...``), modes by
``:Mode:<mode> <axis>``, demands by ``:Demand:Position|Rate|Oscillator``, Off by
``:Mode:Off 1;Off 2;Off 3`` read back with ``:Mode? 1;:Mode? 2;:Mode? 3``. The language has no
command for a free-running sync output (``:Configure:Event`` makes position pulses): it is set at the
controller's console, and the data port shows whether frames come.

``reply_mode: framed`` (serial or TCP: every message answered with error code and length) or
``queries-only`` (GPIB-like: only queries answer; after a command ``*STB?`` bit 7 tells of an error).
"""

from __future__ import annotations

from typing import ClassVar, Literal

import serial

from drivers.acl import AXIS_NUMBER, ERRORS, HEADER, AclCommand, AclError, AclReply, ReplyReader, format_message
from drivers.table_controller import NoOptions, TableController, TableError
from hil.vocabulary import TableMode

WORD = {mode: mode.capitalize() for mode in TableMode}  # ACL's mode words
ERROR_QUEUE_BIT = 0x80  # *STB? bit 7: the error message queue holds an error


class AcutrolOptions(NoOptions):
    """``turntable.controller_options`` of the Acutrol."""

    reply_mode: Literal["framed", "queries-only"] = "framed"


class AcutrolController(TableController):
    """A three-axis Acutrol3000 (module docstring)."""

    name: ClassVar[str] = "acutrol"
    Options: ClassVar[type] = AcutrolOptions
    emulated: ClassVar[str] = "emulators.acutrol_table:AcutrolTable"

    def send(self, *commands: AclCommand) -> AclReply:
        """Send one program message (the commands chained with ``;``) and return its reply; raises
        :class:`TableError` on an error reply or when none comes."""
        message = format_message(list(commands))
        shown = message.strip().decode()
        port = self._io(shown)
        try:
            port.reset_input_buffer()
            port.write(message)
            if self.options.reply_mode == "framed":
                reply = self._read_framed(port, shown)
            elif any(c.query for c in commands):
                raw = port.read_until(b"\n")
                if not raw.endswith(b"\n"):
                    raise TableError(f"turntable: no reply to {shown} within {self.timeout_s} s")
                reply = AclReply(raw.rstrip(b"\r\n").decode("ascii", "replace"))
            else:
                return self._status_after(shown)
        except (serial.SerialException, OSError) as exc:
            raise TableError(f"turntable: {shown} failed on {self.url}: {exc}") from exc
        if not reply.ok:
            raise TableError(f"turntable refused {shown}: error {reply.error} "
                             f"({ERRORS.get(reply.error, 'unknown code')}): {reply.text}")
        return reply

    def _read_framed(self, port, shown: str) -> AclReply:
        reader = ReplyReader()
        head = port.read(HEADER.size)
        try:
            replies = reader.feed(head)
            if len(head) == HEADER.size and not replies:
                replies = reader.feed(port.read(HEADER.unpack(head)[1] + 1))
        except AclError as exc:
            raise TableError(f"turntable: unreadable reply to {shown}: {exc}") from exc
        if not replies:
            raise TableError(f"turntable: no reply to {shown} within {self.timeout_s} s")
        return replies[0]

    def _status_after(self, shown: str) -> AclReply:
        status = int(self.send(AclCommand("*STB", query=True)).text)
        if status & ERROR_QUEUE_BIT:
            raise TableError(f"turntable refused {shown}: the status byte {status} flags an error")
        return AclReply()

    def query(self, path: str, *args) -> str:
        return self.send(AclCommand(path, args, query=True)).text

    def identify(self) -> str:
        return self.send(AclCommand("*IDN", query=True)).text

    def read_position(self, gimbal: str) -> float:
        return float(self.query("Read:Position", AXIS_NUMBER[self._gimbal(gimbal)]))

    def _load_limits(self, gimbal: str, low: float, high: float, rate: float, accel: float) -> None:
        axis = AXIS_NUMBER[gimbal]
        for mode in ("Position", "Rate", "Synthesis"):
            self.send(AclCommand("Limit:Lowposition", (mode, axis, low)),
                      AclCommand("Limit:Highposition", (mode, axis, high)),
                      AclCommand("Limit:Rate", (mode, axis, rate)),
                      AclCommand("Limit:Acceleration", (mode, axis, accel)))

    def _interlocks(self, gimbal: str) -> str:
        state = self.query("Interlock", AXIS_NUMBER[gimbal]).strip().lower()
        return {"close": "closed"}.get(state, state)

    def _close_interlocks(self, gimbal: str) -> None:
        self.send(AclCommand("Interlock:Close", (AXIS_NUMBER[gimbal],)))

    def _mode(self, gimbal: str, mode: str) -> None:
        self.send(AclCommand(f"Mode:{WORD[mode]}", (AXIS_NUMBER[gimbal],)))

    def _position(self, gimbal: str, deg: float) -> None:
        self.send(AclCommand("Demand:Position", (AXIS_NUMBER[gimbal], deg)))

    def _rate(self, gimbal: str, dps: float) -> None:
        self.send(AclCommand("Demand:Rate", (AXIS_NUMBER[gimbal], dps)))

    def _oscillator(self, gimbal: str, amplitude_deg: float, frequency_hz: float, phase_deg: float) -> None:
        self.send(AclCommand("Demand:Oscillator", (AXIS_NUMBER[gimbal], amplitude_deg, frequency_hz, phase_deg)))

    def _off(self) -> dict[str, str]:
        axes = [AXIS_NUMBER[g] for g in self.gimbals]
        self.send(*(AclCommand("Mode:Off", (a,)) for a in axes))
        words = self.send(*(AclCommand("Mode", (a,), query=True) for a in axes)).text.split(";")
        if len(words) != len(axes):
            raise TableError(f"turntable: :Mode? answered {';'.join(words)!r} for {len(axes)} axes")
        return {g: mode_of(w) for g, w in zip(self.gimbals, words)}


def mode_of(answer: str) -> TableMode | str:
    """The interface's mode for a ``:Mode?`` answer: a word, or its first letter as the manual's example shows."""
    answer = answer.strip().lower()
    return next((mode for mode, word in WORD.items() if answer and word.lower().startswith(answer)), answer)
