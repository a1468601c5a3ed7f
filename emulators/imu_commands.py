"""The emulated IMU's configuration dialogue: what it answers on its own port (docs/emulator.md, "Configuration").

A :class:`Responder` per protocol that has one (found by the codec's name, :func:`responder_for`) answers the
messages of :mod:`drivers.config_query` as the device does, from the codec the emulator sends with (its rate and
output settings): the KVH 1750 in its configuration mode, the MTi with its acknowledgements. While the device is in
its configuration mode it sends no frames. :class:`CommandedPty` is the IMU's pseudo-terminal with a thread that
reads what the harness writes and answers it.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path

from drivers.codec import Codec
from drivers.kvh1750 import ENTER_CONFIG, LEAVE_CONFIG, Kvh1750Codec
from drivers.xbus import ERROR, GO_TO_CONFIG, GO_TO_MEASUREMENT, REQ_OUTPUT_CONFIGURATION, xbus_message, xbus_messages
from drivers.xsens import XsensCodec
from emulators.ports import WAIT_S, PtyPort

INVALID_MESSAGE = 0x04  # the MTi's Error code for a message it does not take (ethzasl_xsens_driver mtdef.py)
MAX_LINE = 256  # bytes of an unterminated KVH command line kept (a line noise never ends is dropped)


class Responder(ABC):
    """One emulated device's side of the configuration dialogue."""

    configuring = False  # in its configuration mode: no frames are sent

    @abstractmethod
    def answer(self, data: bytes) -> bytes:
        """The device's replies to the bytes the harness wrote (a message may arrive over several calls)."""


class KvhResponder(Responder):
    """A KVH 1750: normal mode ignores all but =CONFIG,1 (answered "CONFIG,1"); configuration mode answers each
    query "NAME,VALUE", an unknown line "INVALID,<line>", and leaves on =CONFIG,0 without answering."""

    def __init__(self, codec: Kvh1750Codec) -> None:
        self.values = codec.stated_values()
        self.line = bytearray()

    def answer(self, data: bytes) -> bytes:
        self.line += data
        *lines, rest = self.line.replace(b"\r", b"\n").split(b"\n")
        self.line = bytearray(rest[-MAX_LINE:])
        return b"".join(self._reply(text.decode("ascii", "replace").strip().upper()) for text in lines if text.strip())

    def _reply(self, text: str) -> bytes:
        if text == ENTER_CONFIG:
            self.configuring = True
            return b"CONFIG,1\r\n"
        if not self.configuring:
            return b""
        if text == LEAVE_CONFIG:
            self.configuring = False
            return b""
        name = text.removeprefix("?")
        if text.startswith("?") and name in self.values:
            return f"{name},{self.values[name]}\r\n".encode("ascii")
        return f"INVALID,{text}\r\n".encode("ascii")


class XsensResponder(Responder):
    """An MTi: GoToConfig and GoToMeasurement acknowledged (the stream stopped, then resumed), ReqOutputConfiguration
    answered with the items it sends in its configuration state, anything else there with Error 0x04."""

    def __init__(self, codec: XsensCodec) -> None:
        self.outputs = b"".join(xdi.to_bytes(2, "big") + hz.to_bytes(2, "big")
                                for xdi, hz in codec.output_configuration())
        self.pending = bytearray()

    def answer(self, data: bytes) -> bytes:
        self.pending += data
        messages, done = xbus_messages(self.pending)
        del self.pending[:done]
        return b"".join(self._reply(mid, body) for mid, body in messages)

    def _reply(self, mid: int, data: bytes) -> bytes:
        if mid in (GO_TO_CONFIG, GO_TO_MEASUREMENT):
            self.configuring = mid == GO_TO_CONFIG
            return xbus_message(mid + 1)
        if not self.configuring:
            return b""
        if mid == REQ_OUTPUT_CONFIGURATION and not data:
            return xbus_message(REQ_OUTPUT_CONFIGURATION + 1, self.outputs)
        return xbus_message(ERROR, bytes([INVALID_MESSAGE]))


RESPONDERS: dict[str, type[Responder]] = {"kvh1750": KvhResponder, "xsens-mtdata2": XsensResponder}


def responder_for(codec: Codec) -> Responder | None:
    """The emulated device's side of its codec's configuration dialogue; None for a protocol without one."""
    responder = RESPONDERS.get(codec.name)
    return None if responder is None else responder(codec)


class CommandedPty(PtyPort):
    """The IMU's pseudo-terminal, whose device also reads it: a thread hands what the harness writes to the
    ``responder`` and writes its replies; frames written while the responder is configuring are withheld (counted
    in :attr:`withheld`), as the device sends none in its configuration mode. While ``powered()`` is False what
    arrives is lost, and the device starts again in its normal mode."""

    def __init__(self, link: Path | None, responder: Responder, powered: Callable[[], bool] = lambda: True) -> None:
        super().__init__(link)
        self.inbox = bytearray()
        self.responder, self.powered = responder, powered
        self.withheld = 0
        self._writing = threading.Lock()  # a reply never lands inside a frame
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="emulate-imu-commands", daemon=True)
        self._thread.start()

    def write(self, data: bytes, stop: threading.Event) -> bool:
        if self.responder.configuring:
            self.withheld += 1
            return True
        with self._writing:
            return super().write(data, stop)

    def _serve(self) -> None:
        while not self._stop.is_set():
            self.take_input(WAIT_S)
            with self._reading:
                data = bytes(self.inbox)
                self.inbox.clear()
            if not self.powered():  # it hears nothing, and boots in its normal mode
                self.responder.configuring, data = False, b""
            if not data:
                self._stop.wait(WAIT_S / 10)  # a port nobody holds reads as ready at once
                continue
            reply = self.responder.answer(data)
            if not reply or not self.plugged:
                continue
            try:
                with self._writing:
                    super().write(reply, self._stop)
            except OSError:  # unplugged meanwhile: the reply is lost with the line
                pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2 * WAIT_S)
        super().close()
