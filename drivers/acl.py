"""The Acutrol3000 Command Language (ACL, manual TM-8004): one grammar for the client and the emulated table.

A program message is one line: units separated by ``;``. A unit is a header (mnemonics joined by ``:``,
a trailing ``?`` for a query, ``*`` common commands) and, after white space, arguments separated by
commas. Mnemonics are case-insensitive and may be shortened to any leading part of the long name
(``:Demand:Position``, ``:Dem:Pos``, ``:D:P``); where two names of one node share a first letter the
node's first listed wins (TM-8004 2.1 warns that one-letter forms are ambiguous). A unit without a
leading colon continues in the subsystem of the unit before it (``:Mode:Position 1;Rate 2``), the first
of a message at the root. The axis is the first argument (1 inner, 2 middle, 3 outer), ``ALL`` only in
commands (2.4); limits take ``<mode>,<axis>,<value>`` (4.6). The ``:Read`` queries answer without their
``?`` too, as the manual allows for Act2000 programs.

Replies: a query's values joined by ``;`` in the order asked, numbers as ``<NR2>``, modes and interlock
states as words. On a serial or TCP link every message is answered by a framed reply (:func:`frame_reply`):
the error code and the length of the text as two 32-bit little-endian words, then the text and a NUL
(the ACL response block of TM-9374 3.4.2; byte order least significant first, TM-8004 2.4). In the
``queries-only`` mode (GPIB-like, TM-8004 2) only a query is answered, with its text and LF; an error then
shows in bit 7 of ``*STB?``. The public manual does not list the error codes; ours are :data:`ERRORS`.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from typing import ClassVar

AXIS_NUMBER = {"inner": "1", "middle": "2", "outer": "3"}
MODE_WORDS = ("Position", "Rate", "Synthesis", "Off", "Abort", "Arate", "Track")  # a one-letter A is Abort
EOL = b"\n"
MAX_LINE = 32768  # TM-8004 2.5: one message holds up to 32K characters
HEADER = struct.Struct("<ii")  # error code, text length

SYNTAX, ILLEGAL, OUT_OF_RANGE, INTERLOCK = 1, 2, 3, 4
ERRORS = {0: "no error", SYNTAX: "syntax error", ILLEGAL: "illegal command",
          OUT_OF_RANGE: "parameter out of range", INTERLOCK: "interlock open or faulted"}
_NRF = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)(\s*[eE]\s*[+-]?\d+)?")


@dataclass(frozen=True)
class Node:
    """One mnemonic of the tree: ``args`` the argument kinds of its command (None: no command here),
    ``query`` those of its query (None: no query); ``alias`` other accepted spellings; ``optional``
    how many trailing arguments may be left out."""

    name: str
    args: tuple[str, ...] | None = None
    query: tuple[str, ...] | None = None
    children: tuple[Node, ...] = ()
    alias: tuple[str, ...] = ()
    optional: int = 0
    bare_query: bool = False  # a query that needs no ``?`` (the Read subsystem)

    def child(self, mnemonic: str) -> Node | None:
        word = mnemonic.upper()
        return next((c for c in self.children if c.name.upper().startswith(word) or word in c.alias), None)


AXIS, AXES, MODE, NUM, WORD, STATE, INT = "axis", "axis|ALL", "mode", "num", "word", "state", "int"
_LIMIT = {"args": (MODE, AXES, NUM), "query": (MODE, AXIS)}
_READ = {"query": (AXES,), "bare_query": True}
TREE = Node("", children=(
    Node("Read", children=(Node("Position", **_READ), Node("Rate", **_READ), Node("Acceleration", **_READ))),
    Node("Configure", children=(
        Node("Event", args=(AXES, INT, INT, NUM, WORD, NUM), query=(AXIS, INT), optional=3),
        Node("Oscillator", args=(AXES, WORD, NUM, NUM, WORD, WORD), query=(AXIS,)),
    )),
    Node("Demand", children=(
        Node("Position", args=(AXES, NUM), query=(AXIS,)),
        Node("Rate", args=(AXES, NUM), query=(AXIS,)),
        Node("Acceleration", args=(AXES, NUM), query=(AXIS,)),
        Node("Oscillator", args=(AXES, NUM, NUM, NUM), query=(AXIS,)),
        Node("Deltaposition", args=(AXES, NUM), query=(AXIS,)),
    )),
    Node("Interlock", query=(AXIS,), children=(
        Node("Close", args=(AXES,)), Node("Open", args=(AXES,)), Node("Reset", args=()),
    )),
    Node("Interface"),
    Node("Limit", children=(
        Node("Rate", **_LIMIT), Node("Acceleration", **_LIMIT),
        Node("Absolute", query=(AXIS,)),
        Node("Highposition", alias=("HPOS",), args=(MODE, AXES, NUM), query=(MODE, AXIS)),
        Node("Lowposition", alias=("LPOS",), args=(MODE, AXES, NUM), query=(MODE, AXIS)),
    )),
    Node("Mode", args=(AXES, MODE), query=(AXIS,), children=tuple(
        Node(word, args=(AXES,)) for word in MODE_WORDS)),
    Node("Query", children=(Node("Error", query=(INT,)),)),
    Node("Status"),
    Node("Utility", children=(Node("Format", args=(WORD,), query=()),)),
))
COMMON = {"*IDN": ((), None), "*STB": ((), None), "*CLS": (None, ())}  # name -> (query args, command args)


class AclError(ValueError):
    """A unit the language refuses; ``code`` is the error code a table replies with (:data:`ERRORS`)."""

    def __init__(self, message: str, code: int = SYNTAX) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True, slots=True)
class AclCommand:
    """One unit: its path of long names (``Demand:Position``, ``*IDN``), whether it is a query, and its
    arguments (axis as ``"1"``..``"3"`` or ``"ALL"``, modes as long words, numbers as float)."""

    path: str
    args: tuple[str | float, ...] = ()
    query: bool = False

    @property
    def header(self) -> str:
        return (self.path if self.path.startswith("*") else ":" + self.path) + ("?" if self.query else "")

    def text(self) -> str:
        """The unit as the client writes it: long names, arguments in the manual's order."""
        args = ",".join(a if isinstance(a, str) else f"{a:.10g}" for a in self.args)
        return self.header + (" " + args if args else "")


@dataclass(frozen=True, slots=True)
class AclReply:
    """A reply: its text (the queries' values joined by ``;``) and the error code (0 when accepted)."""

    text: str = ""
    error: int = 0

    @property
    def ok(self) -> bool:
        return self.error == 0


def parse_message(line: bytes | str, axes: int = 3) -> list[AclCommand]:
    """The units of one program message, resolved in the tree; raises :class:`AclError` at the first bad one.
    ``axes`` is how many axes the table has (an axis number beyond them is out of range)."""
    text = (line.decode("ascii", "replace") if isinstance(line, bytes) else line).strip()
    units, level, path = [], TREE, ""
    for unit in text.split(";"):
        unit = unit.strip()
        if not unit:
            raise AclError(f"empty unit in {text!r}")
        command, level, path = _parse_unit(unit, level, path, axes)
        units.append(command)
    return units


def _parse_unit(unit: str, level: Node, path: str, axes: int) -> tuple[AclCommand, Node, str]:
    header, _, rest = unit.partition(" ")
    rest = rest.strip()
    query = header.endswith("?")
    header = header.removesuffix("?")
    if header.startswith("*"):
        kinds = COMMON.get(header.upper(), (None, None))[0 if query else 1]
        if kinds is None:
            raise AclError(f"unknown common command {unit!r}", ILLEGAL)
        return AclCommand(header.upper(), _args(kinds, rest, unit, 0, axes, query), query), level, path
    if header.startswith(":"):
        level, path, header = TREE, "", header[1:]
    node, names = level, []
    for mnemonic in header.split(":"):
        found = node.child(mnemonic) if mnemonic else None
        if found is None:
            under = ":".join(filter(None, (path, *names)))
            raise AclError(f"unknown command {unit!r} ({mnemonic!r} is not under {':' + under if under else 'the root'})",
                           ILLEGAL)
        parent, node = node, found
        names.append(found.name)
    query = query or (node.bare_query and node.args is None)
    kinds = node.query if query else node.args
    full = ":".join(filter(None, (path, *names)))
    if kinds is None:
        raise AclError(f"{':' + full}{'?' if query else ''} is not a {'query' if query else 'command'}", ILLEGAL)
    command = AclCommand(full, _args(kinds, rest, unit, node.optional, axes, query), query)
    return command, parent, full.rpartition(":")[0]


def _args(kinds: tuple[str, ...], rest: str, unit: str, optional: int, axes: int, query: bool) -> tuple:
    tokens = [t.strip() for t in rest.split(",")] if rest else []
    if kinds and kinds[0] == MODE and len(tokens) == len(kinds) - 1 and query:
        kinds = kinds[1:]  # a position limit is also queried by axis alone (TM-8004 4.6.6)
    if not len(kinds) - optional <= len(tokens) <= len(kinds):
        raise AclError(f"{unit!r} takes {len(kinds)} argument(s), got {len(tokens)}")
    return tuple(_arg(k, t, unit, axes, query) for k, t in zip(kinds, tokens))


def _arg(kind: str, token: str, unit: str, axes: int, query: bool) -> str | float:
    word = token.upper()
    if kind in (AXIS, AXES):
        if word == "ALL" and kind == AXES and not query:
            return "ALL"
        if not word.isdigit() or not 1 <= int(word) <= axes:
            raise AclError(f"axis {token!r} in {unit!r}: the table has axes 1..{axes}"
                           + (", ALL only in commands" if word == "ALL" else ""), OUT_OF_RANGE)
        return str(int(word))
    if kind == MODE:
        found = next((m for m in MODE_WORDS if word and m.upper().startswith(word)), None)
        if found is None:
            raise AclError(f"mode {token!r} in {unit!r}: one of {', '.join(MODE_WORDS)}", OUT_OF_RANGE)
        return found
    if kind == INT:
        if not word.lstrip("+-").isdigit():
            raise AclError(f"integer {token!r} in {unit!r}")
        return float(int(word))
    if kind == NUM:
        if not _NRF.fullmatch(token):
            raise AclError(f"number {token!r} in {unit!r}")
        return float(token.replace(" ", ""))
    if not token:
        raise AclError(f"empty argument in {unit!r}")
    return token


def format_message(commands: list[AclCommand] | AclCommand) -> bytes:
    """One program message of ``commands`` (chained with ``;``), checked against the grammar, with its LF."""
    commands = [commands] if isinstance(commands, AclCommand) else commands
    line = ";".join(c.text() for c in commands)
    parse_message(line)  # refuse to send what a table could not parse
    return line.encode("ascii") + EOL


def frame_reply(reply: AclReply) -> bytes:
    """A serial or TCP reply: error code and text length (two int32, little-endian), the text, a NUL."""
    text = reply.text.encode("ascii", "replace")
    return HEADER.pack(reply.error, len(text)) + text + b"\0"


@dataclass
class ReplyReader:
    """Reassembles framed replies from the bytes of a link; :meth:`feed` returns the complete ones."""

    _buf: bytearray = field(default_factory=bytearray)
    limit: ClassVar[int] = MAX_LINE

    def feed(self, data: bytes) -> list[AclReply]:
        self._buf += data
        out = []
        while len(self._buf) >= HEADER.size:
            code, length = HEADER.unpack_from(self._buf)
            if not 0 <= length <= self.limit or code < 0:
                raise AclError(f"not an ACL reply: header {bytes(self._buf[:HEADER.size]).hex()}")
            end = HEADER.size + length + 1
            if len(self._buf) < end:
                break
            out.append(AclReply(self._buf[HEADER.size:end - 1].decode("ascii", "replace"), code))
            del self._buf[:end]
        return out


class AclCodec:
    """The language as a command protocol of the codec registry (no data frames)."""

    name: ClassVar[str] = "acl"
    kind: ClassVar[str] = "command"


class LineFramer:
    """Splits a byte stream into lines (LF, a CR before it dropped); over-long lines are dropped and counted."""

    def __init__(self, limit: int = MAX_LINE) -> None:
        self._buf = bytearray()
        self.limit = limit
        self.dropped = 0

    def feed(self, data: bytes) -> list[bytes]:
        """Complete lines in ``data``, without their line ends."""
        self._buf += data
        *lines, rest = self._buf.split(b"\n")
        self._buf = bytearray(rest)
        if len(self._buf) > self.limit:
            self._buf.clear()
            self.dropped += 1
        out = []
        for line in lines:
            if len(line) > self.limit:
                self.dropped += 1
            else:
                out.append(bytes(line.rstrip(b"\r")))
        return out
