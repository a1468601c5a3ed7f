"""Turntable commands ``acl``: an ASCII subset of the Acutrol command language, one reply per line.

Lines end in CR LF. A reply is the answer text, or ``?<code> <text>`` on error. Replies to queries:
``*IDN?`` free text, ``*STB?`` an integer, ``:Mode?`` one of P/R/S/O, ``:Read:Position?`` degrees,
``:Interlock?`` ``Closed`` or ``Open``, ``:Limit:*?`` the values; other commands answer ``OK``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

AXIS_NUMBER = {"inner": "1", "middle": "2", "outer": "3"}
AXES = ("1", "2", "3", "ALL")
MODES = {"Position": "P", "Rate": "R", "Synthesis": "S", "Off": "O"}  # mode -> its ``:Mode?`` letter
MOTION_MODES = {"swing": "Synthesis", "rate": "Rate", "positions": "Position", "static": "Position"}
"""The table mode that performs each ``turntable.motion.kind``: a swing is an oscillation about the centre
(Synthesis), a rate a constant demanded rate (Rate), static and positions held position demands
(Position). An axis of a swing with no amplitude may be commanded in Position, which holds it alike."""
EOL = b"\r\n"
MAX_LINE = 256

# Error codes of ``?<code> <text>`` replies.
ERR_UNKNOWN_COMMAND = 100
ERR_BAD_ARGUMENT = 101
ERR_LIMIT = 200
ERR_INTERLOCK = 201

# header -> argument kinds: "axis", "num", "mode", "onoff".
COMMANDS: dict[str, tuple[str, ...]] = {
    "*IDN?": (), "*STB?": (),
    ":Mode": ("axis", "mode"), ":Mode?": ("axis",),
    ":Demand:Position": ("axis", "num"), ":Demand:Rate": ("axis", "num"),
    ":Demand:Oscillator": ("axis", "num", "num", "num"),
    ":Read:Position?": ("axis",),
    ":Interlock:Close": ("axis",), ":Interlock:Open": ("axis",), ":Interlock:Reset": ("axis",),
    ":Interlock?": ("axis",),
    ":Limit:Position": ("axis", "num", "num"), ":Limit:Rate": ("axis", "num"),
    ":Limit:Acceleration": ("axis", "num"),
    ":Limit:Position?": ("axis",), ":Limit:Rate?": ("axis",), ":Limit:Acceleration?": ("axis",),
    ":Configure:Sync": ("onoff",),
}


class AclError(ValueError):
    """A line that is not a valid command or reply; ``code`` is the reply code a table would send."""

    def __init__(self, message: str, code: int = ERR_BAD_ARGUMENT) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True, slots=True)
class AclCommand:
    """One command: its header (e.g. ``:Demand:Position``) and arguments (axis and words as str, numbers as float)."""

    header: str
    args: tuple[str | float, ...] = ()

    @property
    def axis(self) -> str | None:
        return self.args[0] if COMMANDS.get(self.header, ())[:1] == ("axis",) else None


@dataclass(frozen=True, slots=True)
class AclReply:
    """One reply line: the text, and the error code when the table refused the command."""

    text: str
    error: int | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def _format_arg(value: str | float) -> str:
    return value if isinstance(value, str) else f"{value:.10g}"


def _parse_arg(kind: str, token: str, line: str) -> str | float:
    token = token.strip()
    if kind == "axis":
        value = token.upper()
        ok = value in AXES
    elif kind == "mode":
        value = next((m for m in MODES if m.lower() == token.lower()), token)
        ok = value in MODES
    elif kind == "onoff":
        value = token.upper()
        ok = value in ("ON", "OFF")
    else:
        try:
            value = float(token)
        except ValueError:
            value, ok = token, False
        else:
            ok = value == value and abs(value) != float("inf")
    if not ok:
        raise AclError(f"acl: bad {kind} argument {token!r} in {line!r}")
    return value


class AclCodec:
    """Format and parse ``acl`` command and reply lines (bytes on the wire, CR LF terminated)."""

    name: ClassVar[str] = "acl"
    kind: ClassVar[str] = "command"

    def format_command(self, command: AclCommand) -> bytes:
        """The command line, validated, with its CR LF."""
        line = command.header + (" " + ",".join(_format_arg(a) for a in command.args) if command.args else "")
        self.parse_command(line)  # refuse to send what a table could not parse
        return line.encode("ascii") + EOL

    def parse_command(self, line: bytes | str) -> AclCommand:
        """The command of one line (with or without its line end); raises :class:`AclError`."""
        text = line.decode("ascii", "replace") if isinstance(line, bytes) else line
        text = text.strip()
        header, _, rest = text.partition(" ")
        kinds = next((v for k, v in COMMANDS.items() if k.lower() == header.lower()), None)
        if kinds is None:
            raise AclError(f"acl: unknown command {header!r}", ERR_UNKNOWN_COMMAND)
        header = next(k for k in COMMANDS if k.lower() == header.lower())
        tokens = rest.split(",") if rest.strip() else []
        if len(tokens) != len(kinds):
            raise AclError(f"acl: {header} takes {len(kinds)} argument(s), got {len(tokens)} in {text!r}")
        return AclCommand(header, tuple(_parse_arg(k, t, text) for k, t in zip(kinds, tokens)))

    def format_reply(self, reply: AclReply) -> bytes:
        text = reply.text if reply.ok else f"?{reply.error} {reply.text}"
        return text.replace("\r", " ").replace("\n", " ").encode("ascii", "replace") + EOL

    def parse_reply(self, line: bytes | str) -> AclReply:
        text = (line.decode("ascii", "replace") if isinstance(line, bytes) else line).strip()
        if not text.startswith("?"):
            return AclReply(text)
        code, _, message = text[1:].partition(" ")
        if not code.isdigit():
            raise AclError(f"acl: malformed error reply {text!r}")
        return AclReply(message, int(code))


class LineFramer:
    """Splits a byte stream into lines (CR LF or LF); over-long lines are dropped and counted."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.dropped = 0

    def feed(self, data: bytes) -> list[bytes]:
        """Complete lines in ``data``, without their line ends."""
        self._buf += data
        *lines, rest = self._buf.split(b"\n")
        self._buf = bytearray(rest)
        if len(self._buf) > MAX_LINE:
            self._buf.clear()
            self.dropped += 1
        out = []
        for line in lines:
            if len(line) > MAX_LINE:
                self.dropped += 1
            else:
                out.append(bytes(line.rstrip(b"\r")))
        return out
