"""Asking an IMU for its own configuration on its port before a trial (docs/devices.md, "Configuration check").

A codec whose protocol has a configuration dialogue returns a :class:`ConfigDialogue` from
:meth:`drivers.codec.Codec.config_dialogue`; the dialogue talks to the device through an :class:`Exchange` (a
request written, the device's reply found in what arrives, streaming frames around it ignored) and gives what the
device said as a :class:`DeviceConfig`: its replies verbatim and the config keys they set. A device that stays
silent raises :class:`NoAnswer`, a reply the codec cannot read :class:`UnreadableReply`.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

REPLY_TIMEOUT_S = 1.0  # longest wait for one reply (the KVH manual: a ?BIT reply typically within 100 ms)
T = TypeVar("T")


class NoAnswer(Exception):
    """The device did not answer a request within its timeout (a read-only line, a one-way converter)."""


class UnreadableReply(ValueError):
    """The device answered something the codec cannot read; the message names the reply."""


class Chunk(Protocol):
    data: bytes


class BytePort(Protocol):
    """What an exchange needs of a transport (:class:`drivers.transport.SerialTransport`): its reads' chunks
    (:class:`drivers.codec.RawChunk`) and a write."""

    def read(self) -> list[Chunk]: ...

    def write(self, data: bytes) -> None: ...


@dataclass(frozen=True)
class Setting:
    """One config key as the device states it: the key, the value in the config's terms, the reply it came from."""

    key: str
    value: Any
    reply: str


@dataclass(frozen=True)
class DeviceConfig:
    """What a device said of its configuration: each request's reply as received, and the settings read from them."""

    replies: dict[str, str]
    settings: tuple[Setting, ...]

    def mismatches(self, expected: dict[str, Any]) -> list[str]:
        """One line per setting that differs from ``expected`` ({config key: the config's value}), naming the key,
        the device's reply and the config's value; a key the device did not state is not judged."""
        return [f"{s.key}: the IMU says {s.reply!r} ({_shown(s.value)}), the config {_shown(expected[s.key])}"
                for s in self.settings if s.key in expected and not _same(s.value, expected[s.key])]

    def as_record(self) -> dict[str, Any]:
        """result.json's ``record.imu_config`` of a device that answered."""
        return {"answered": True, "replies": dict(self.replies), "settings": {s.key: s.value for s in self.settings}}


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float | int) and isinstance(b, float | int):
        return math.isclose(a, b, rel_tol=1e-9)
    return a == b


def _shown(value: Any) -> str:
    return f"{value:g} Hz" if isinstance(value, float | int) and not isinstance(value, bool) else str(value)


class Exchange:
    """Requests and replies on a byte port: each reply is looked for in everything that arrived since its request."""

    def __init__(self, port: BytePort, timeout_s: float = REPLY_TIMEOUT_S) -> None:
        self.port, self.timeout_s = port, timeout_s
        self.pending = bytearray()

    def send(self, request: bytes) -> None:
        """Write ``request`` and forget what arrived before it."""
        self.pending.clear()
        self.port.write(request)

    def ask(self, request: bytes, find: Callable[[bytearray], T | None], what: str) -> T:
        """Write ``request`` and read until ``find`` returns the reply from the bytes received; raises
        :class:`NoAnswer` naming ``what`` after the timeout."""
        self.send(request)
        deadline = time.monotonic() + self.timeout_s
        while True:
            reply = find(self.pending)
            if reply is not None:
                return reply
            if time.monotonic() > deadline:
                raise NoAnswer(f"no answer to {what} within {self.timeout_s:g} s")
            for chunk in self.port.read():
                self.pending += chunk.data


class ConfigDialogue(ABC):
    """One protocol's configuration query: into the device's configuration mode, the questions, back out."""

    @abstractmethod
    def query(self, port: Exchange) -> DeviceConfig:
        """What the device says; the device is left streaming however this ends. Raises :class:`NoAnswer` or
        :class:`UnreadableReply`."""
