"""The emulated Ideal Aerosmith rate table: the command set of :mod:`drivers.aerosmith_controller`, carried out
on one column of the servo (``controller_options.axis``).

``MOV`` / ``RMO`` move to a position (Position mode), ``JOG`` turns at a rate (Rate mode), ``SGO`` starts
the sinusoid of ``AMP`` and ``FRQ`` (or ``PER``) about the last position (Synthesis mode; ``CYC0``:
continuous, the only count emulated), ``STO`` stops (Off). ``VEL`` is the rate of position moves, ``ACL``
the acceleration of every motion. ``DIR``, ``HOF``, ``SAV`` are kept and acknowledged; ``HOM`` moves to 0.
"""

from __future__ import annotations

import re
import sys
from collections import Counter

from drivers.aerosmith_controller import PROMPT, SILENT, STA_ENABLED, STA_FAULT, STA_MODES, STA_MOVING
from emulators.servo import Refused, Servo
from hil.samples import GIMBAL_AXES
from hil.vocabulary import TableMode

_LINE = re.compile(r"([A-Za-z]{3})\s*([-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)?")
_KEPT = ("DIR", "HOF", "SAV")


class AerosmithTable:
    """The emulated table's side of the serial link (module docstring); ``options`` the controller's."""

    def __init__(self, servo: Servo, options, log: bool = False) -> None:
        self.servo = servo
        self.k = GIMBAL_AXES.index(options.axis)
        self.print_log = log
        self.received: Counter[str] = Counter()
        self.log: list[tuple[str, int]] = []
        self.offs = 0
        self.sine = {"AMP": 0.0, "FRQ": 0.0}
        self.kept: dict[str, float] = {}
        self._buf = b""

    def reset(self) -> None:
        self._buf = b""

    def modes(self) -> str:
        return self.servo.mode(self.k).capitalize()

    def feed(self, data: bytes) -> bytes:
        """The bytes answered to ``data``: ``STO`` acts at once, other commands at their line end."""
        self._buf += data
        out = []
        while True:
            head = self._buf.lstrip(b"\r\n ")
            if head[:3].upper() == b"STO":
                self._buf = head[3:]
                out.append(self.answer("STO"))
                continue
            end = min((i for i in (head.find(b"\r"), head.find(b"\n")) if i >= 0), default=-1)
            if end < 0:
                self._buf = head
                return b"".join(out)
            self._buf = head[end + 1:]
            out.append(self.answer(head[:end].decode("ascii", "replace")))

    def answer(self, line: str) -> bytes:
        """The reply line and prompt to one command (nothing for the silent ones)."""
        line = line.strip()
        match = _LINE.fullmatch(line)
        name = match.group(1).upper() if match else line[:3].upper()
        try:
            if match is None:
                raise Refused(f"not a command: {line!r}", "argument")
            value = float(match.group(2)) if match.group(2) else None
            reply = self._run(name, value)
            code = 0
        except Refused as exc:
            reply, code = f"ERR {exc}", 1
        self.received[name] += 1
        self.log.append((line, code))
        if self.print_log:
            print(f"aerosmith: {line} -> {reply or 'OK'}", file=sys.stderr, flush=True)
        if name in SILENT and code == 0:
            return b""
        return f"{reply}\r\n{PROMPT}\r\n".encode("ascii")

    def _run(self, name: str, value: float | None) -> str:
        servo, axes = self.servo, [self.k]
        needs = {"VEL", "ACL", "MOV", "RMO", "JOG", "AMP", "FRQ", "PER", "CYC", "MCO", "DIR", "HOF"}
        if name in needs and value is None:
            raise Refused(f"{name} needs a number", "argument")
        if name == "STO":
            servo.set_mode(axes, TableMode.OFF)
            self.offs += 1
            return ""
        if name in ("VEL", "ACL"):
            kind = "rate" if name == "VEL" else "accel"
            for mode in (TableMode.POSITION, TableMode.SYNTHESIS) if name == "VEL" else TableMode:
                servo.set_limit(mode, axes, kind, value)
            return "OK"
        if name in ("MOV", "RMO", "HOM"):
            servo.demand(axes, "delta" if name == "RMO" else "position", (value or 0.0,))
            servo.set_mode(axes, TableMode.POSITION)
            return "OK"
        if name == "JOG":
            servo.demand(axes, "rate", (value,))
            servo.set_mode(axes, TableMode.RATE)
            return ""
        if name in ("AMP", "FRQ", "PER"):
            self.sine["FRQ" if name == "PER" else name] = 1.0 / value if name == "PER" else value
            return "OK"
        if name == "CYC":
            if value != 0:
                raise Refused("only continuous sinusoids (CYC0) are emulated", "argument")
            return "OK"
        if name == "SGO":
            servo.demand(axes, "oscillator", (self.sine["AMP"], self.sine["FRQ"], 0.0))
            servo.set_mode(axes, TableMode.SYNTHESIS)
            return ""
        if name in ("PPO", "PVE"):
            position, rate, _ = servo.reading(self.k)
            return f"{position if name == 'PPO' else rate:.6f}"
        if name == "STA":
            return str(self._status())
        if name == "MCO":
            position, rate, _ = servo.reading(self.k)
            return "1" if abs(position - servo.demands[self.k].position) <= value and abs(rate) < 1e-9 else "0"
        if name in _KEPT:
            self.kept[name] = value
            return "OK"
        raise Refused(f"unknown command {name}", "argument")

    def _status(self) -> int:
        state = self.servo.interlock_state(self.k)
        rate = self.servo.reading(self.k)[1]
        mode = STA_MODES.index(self.servo.mode(self.k))
        return (mode | (STA_ENABLED if state == "closed" else 0) | (STA_FAULT if state == "fault" else 0)
                | (STA_MOVING if abs(rate) > 1e-9 else 0))
