"""The emulated Acutrol3000: program messages in the language of :mod:`drivers.acl`, carried out on the servo.

Each message is parsed whole against the grammar, then its units run in order until one is refused;
the reply (framed, or in ``queries-only`` mode a query's text and LF) holds the queries' values joined
by ``;``, or the refused unit's error code and text. ``:Mode?`` answers a word (Position, Rate,
Synthesis, Off), ``:Interlock? <axis>`` Close, Open or Fault, ``*STB?`` the IEEE 488.2 status byte
(bit 0 a latched interlock fault, bit 7 an error since the last read, bit 6 either; reading clears bit
7). Units the table keeps but does not act on: ``:Configure:Event`` and ``:Configure:Oscillator``
(position pulses and oscillator slewing are not emulated), ``:Utility:Format Float``.
"""

from __future__ import annotations

import sys
from collections import Counter

from drivers.acl import (
    AXIS_NUMBER,
    ERRORS,
    ILLEGAL,
    INTERLOCK,
    OUT_OF_RANGE,
    AclCommand,
    AclError,
    AclReply,
    LineFramer,
    frame_reply,
    parse_message,
)
from emulators.servo import Refused, Servo
from hil.samples import GIMBAL_AXES
from hil.vocabulary import TableMode

IDN = "turntable-hil,emulated Acutrol3000,0,1"
COLUMN = {AXIS_NUMBER[g]: k for k, g in enumerate(GIMBAL_AXES)}  # axis "1".."3" -> servo column
MODE = {mode.capitalize(): mode for mode in TableMode} | {"Abort": TableMode.OFF}  # ACL's words; Abort stops like Off
WORD = {mode: mode.capitalize() for mode in TableMode}
LIMIT_KIND = {"Limit:Rate": "rate", "Limit:Acceleration": "accel", "Limit:Lowposition": "low",
              "Limit:Highposition": "high"}
REFUSAL = {"limit": OUT_OF_RANGE, "argument": OUT_OF_RANGE, "interlock": INTERLOCK}


class AcutrolTable:
    """The emulated controller's side of the command link (module docstring); ``options`` the
    controller's (``reply_mode``)."""

    def __init__(self, servo: Servo, options, log: bool = False) -> None:
        self.servo = servo
        self.framed = options.reply_mode == "framed"
        self.print_log = log
        self.framer = LineFramer()
        self.received: Counter[str] = Counter()
        self.log: list[tuple[str, int]] = []  # every message and its error code (0: accepted)
        self.offs = 0
        self._error = False
        self._turned_off: set[int] = set()
        self._kept: dict[tuple, tuple] = {}

    def reset(self) -> None:
        self.framer = LineFramer()

    def modes(self) -> str:
        """The axes' modes as ``:Mode?`` words, axis 1 first."""
        return ",".join(WORD[self.servo.mode(COLUMN[a])] for a in "123")

    def feed(self, data: bytes) -> bytes:
        return b"".join(self.answer(line) for line in self.framer.feed(data) if line.strip())

    def answer(self, line: bytes) -> bytes:
        """The reply bytes to one program message (without its line end)."""
        text = line.decode("ascii", "replace").strip()
        self._turned_off: set[int] = set()
        try:
            commands = parse_message(text)
            values = [v for v in (self._run(c) for c in commands) if v is not None]
            reply = AclReply(";".join(values))
        except AclError as exc:
            reply, commands = AclReply(str(exc), exc.code), []
        except Refused as exc:
            reply = AclReply(str(exc), REFUSAL[exc.reason])
        self._error |= not reply.ok
        self.offs += len(self._turned_off) == 3  # one message that turned every axis Off
        self.log.append((text, reply.error))
        if self.print_log:
            print(f"acutrol: {text} -> {'OK' if reply.ok else f'error {reply.error}: {reply.text}'}",
                  file=sys.stderr, flush=True)
        if self.framed:
            return frame_reply(reply)
        return (reply.text.encode("ascii", "replace") + b"\n") if any(c.query for c in commands) else b""

    def _run(self, c: AclCommand) -> str | None:
        self.received[c.header] += 1
        path, args = c.path, c.args
        if path == "*IDN":
            return IDN
        if path == "*STB":
            return str(self._status())
        if path == "*CLS":
            self._error = False
            return None
        if c.query:
            return self._query(c)
        if path.startswith("Mode"):
            word = path.partition(":")[2] or args[1]
            if word not in MODE:
                raise AclError(f"mode {word} is not available on this table", ILLEGAL)
            axes = self._axes(args[0])
            self.servo.set_mode(axes, MODE[word])
            self._turned_off |= set(axes) if word == "Off" else set()
        elif path.startswith("Demand:"):
            kind = path.partition(":")[2].lower().replace("deltaposition", "delta")
            if kind == "acceleration":
                raise AclError("acceleration demands are for Track mode, which this table lacks", ILLEGAL)
            self.servo.demand(self._axes(args[0]), kind, tuple(args[1:]))
        elif path.startswith("Interlock:"):
            action = path.partition(":")[2].lower()
            self.servo.interlock(self._axes(args[0]) if args else [], action)
        elif path in LIMIT_KIND:
            mode = MODE.get(args[0])
            if mode is None:
                raise AclError(f"{c.text()}: no {args[0]} profiler on this table", OUT_OF_RANGE)
            self.servo.set_limit(mode, self._axes(args[1]), LIMIT_KIND[path], args[2])
        else:  # Configure:Event, Configure:Oscillator, Utility:Format: kept for their queries
            if path == "Utility:Format" and not "FLOAT".startswith(str(args[0]).upper()):
                raise AclError("only the Float format is emulated", OUT_OF_RANGE)
            self._kept[(path, *args[:1])] = args[1:]
        return None

    def _query(self, c: AclCommand) -> str:
        path, args = c.path, c.args
        if path == "Query:Error":
            return ERRORS.get(int(args[0]), "unknown error code")
        if path == "Utility:Format":
            return "Float"
        if path.startswith("Limit:"):
            mode, axis = (args[0], args[1]) if len(args) == 2 else ("Position", args[0])
            k = COLUMN[axis]
            if path == "Limit:Absolute":
                lim = self.servo.mode_limits[TableMode.POSITION]
                return ",".join(f"{v:.5f}" for v in (lim.rate_dps[k], lim.accel_dps2[k], 0.0, lim.position_min_deg[k],
                                                      lim.position_max_deg[k], lim.rate_dps[k]))
            if mode not in MODE:
                raise AclError(f"{c.text()}: no {mode} profiler on this table", OUT_OF_RANGE)
            return f"{self.servo.limit(MODE[mode], k, LIMIT_KIND[path]):.5f}"
        k = COLUMN[args[0]]
        if path == "Mode":
            return WORD[self.servo.mode(k)]
        if path == "Interlock":
            return {"closed": "Close", "open": "Open", "fault": "Fault"}[self.servo.interlock_state(k)]
        if path.startswith("Read:"):
            value = self.servo.reading(k)[("Read:Position", "Read:Rate", "Read:Acceleration").index(path)]
            return f"{value:.6f}"
        if path.startswith("Demand:"):
            d = self.servo.demands[k]
            return {"Demand:Position": f"{d.position:.5f}", "Demand:Rate": f"{d.rate:.5f}",
                    "Demand:Oscillator": ",".join(f"{v:.5f}" for v in d.oscillator)}.get(path, "0.00000")
        kept = self._kept.get((path, args[0]))
        if kept is None:
            raise AclError(f"{c.text()}: not configured", OUT_OF_RANGE)
        return ",".join(v if isinstance(v, str) else f"{v:g}" for v in kept)

    def _axes(self, axis: str) -> list[int]:
        return [COLUMN[a] for a in "123"] if axis == "ALL" else [COLUMN[axis]]

    def _status(self) -> int:
        fault = any(self.servo.interlock_state(k) == "fault" for k in range(3))
        status = int(fault) | (0x80 if self._error else 0)
        self._error = False
        return status | (0x40 if status else 0)
