"""Transports: a byte port chosen by a pyserial URL, and a CAN bus through python-can.

Both return whatever has arrived as :class:`RawChunk` records and never wait for a whole frame.
:func:`open_serial` opens every pyserial URL of the harness (device streams and the table's command
port), so that both speak to lab serial servers (ser2net) alike and fail with the same one-line message.
"""

from __future__ import annotations

import re
import socket
import sys
import termios
import time
from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any
from urllib.parse import parse_qs, urlsplit

import can
import serial

from drivers.codec import RawChunk
from drivers.pty_guard import PtyGuard
from drivers.tap import message_to_chunk
from hil.inputs import InputError

POLL_S = 0.05  # longest a read waits, so a reader thread notices a stop request promptly
CAN_READ_MAX = 2000  # CAN messages one read takes at most (1/6 s of a 2 kHz IMU sending six a sample)
# bytes asked for a CAN socket's receive buffer (docs/harness.md, "CAN over udp_multicast"): granted twice that,
# 1.7 s of a 2 kHz IMU's six messages a sample, the kernel charging each small datagram 832 bytes on the loopback
CAN_RECEIVE_BUFFER = 1 << 23
SOCKET_READ_MAX = 1 << 16  # bytes taken from a socket:// port in one read (a TCP receive buffer's worth)


class TransportError(InputError, OSError):
    """The transport cannot be opened or has gone away (unplugged, remote closed)."""


def serial_url(url: str) -> str:
    """``url`` as pyserial needs it: an ``rfc2217://`` URL gets ``ign_set_control`` unless it says so already.

    pyserial waits for the server to echo each SET_CONTROL it sends while opening (flow control, DTR, RTS);
    ser2net 4.3 does not answer the DTR one ("timeout while waiting for option 'control'" after 3 s), other
    servers answer with other values ("remote rejected value for option 'control'").
    """
    if not url.startswith("rfc2217://"):
        return url
    parts = urlsplit(url)
    if "ign_set_control" in parse_qs(parts.query, keep_blank_values=True):
        return url
    return parts._replace(query="&".join(filter(None, (parts.query, "ign_set_control")))).geturl()


def open_serial(url: str, name: str, **settings: Any) -> serial.SerialBase:
    """``serial.serial_for_url`` on :func:`serial_url` (``url``); raises :class:`TransportError` with one line:
    ``"<name>: cannot open <url>: <reason>"``.

    An RFC 2217 port starts with what arrives after pyserial's open. That open empties its input, then has
    the server purge its transmit buffer, which ser2net does by dropping bytes already on their way: kept,
    the first frames would be followed by a gap of a few.
    """
    try:
        port = serial.serial_for_url(serial_url(url), **settings)
        if url.startswith("rfc2217://"):
            port.read(port.in_waiting)  # what came before the purge was answered
    except (serial.SerialException, OSError, ValueError, termios.error) as exc:
        # termios.error: a pty that hangs up while pyserial sets it up (its flush fails with EIO)
        raise TransportError(f"{name}: cannot open {url}: {_open_failure(exc)}") from exc
    return port


def _open_failure(exc: BaseException) -> str:
    """Why an open failed, in a few words: the operating system's reason when pyserial's exception wraps
    one (pyserial repeats the port around it), else pyserial's own first line without the port."""
    error: BaseException | None = exc
    while error is not None:
        if isinstance(error, BlockingIOError):  # the non-blocking flock of exclusive=True
            return "in use by another program (locked)"
        match error.args:
            case (int(), str(text)) if not isinstance(error, serial.SerialException):  # OSError, termios.error
                return text[:1].lower() + text[1:]
        error = error.__cause__ or error.__context__
    text = (str(exc).splitlines() or [type(exc).__name__])[0]
    return re.sub(r"^could not open port \S+: ", "", text, flags=re.IGNORECASE)


class Transport(ABC):
    """A source of raw chunks that can be reopened after it fails."""

    stream: str
    address: str  # the port as the config names it, for messages
    byte_stream: bool = False  # a read returns all bytes that have arrived (several frames after a wait)

    @abstractmethod
    def open(self) -> None:
        """Open the device; raises :class:`TransportError`."""

    @abstractmethod
    def read(self) -> list[RawChunk]:
        """What has arrived (nothing after ``POLL_S`` of silence); raises :class:`TransportError`."""

    @abstractmethod
    def close(self) -> None:
        """Release the device; safe to call twice."""


class SerialTransport(Transport):
    """A pyserial port by URL: ``/dev/ttyUSB0``, ``socket://host:port``, ``rfc2217://host:port``, ``loop://``."""

    byte_stream = True

    def __init__(self, url: str, baudrate: int, stream: str) -> None:
        self.url, self.baudrate, self.stream = url, baudrate, stream
        self.address = url
        self.port: serial.SerialBase | None = None
        self._pty = PtyGuard(url)  # never reopened onto another program's pty (drivers.pty_guard)

    def open(self) -> None:
        if not self._pty.admits():
            raise TransportError(f"{self.stream}: {self.url} is now another program's pseudo-terminal; not reopening")
        # exclusive: an advisory lock, so a second reader (a stale session of another process
        # reconnecting to a reused pty number) cannot share the port and split its bytes
        port = open_serial(self.url, self.stream, baudrate=self.baudrate, timeout=POLL_S, exclusive=True)
        try:
            port.set_low_latency_mode(True)  # FTDI and similar USB adapters: no 16 ms batching
        except (AttributeError, NotImplementedError, OSError, ValueError):
            pass  # not a local UART (pty, socket, rfc2217): nothing to tune
        self.port = port

    def read(self) -> list[RawChunk]:
        if self.port is None:
            raise TransportError(f"{self.stream}: {self.url} is not open")
        try:
            data = self.port.read(self.port.in_waiting or 1)
            if data:
                data += self._arrived()
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"{self.stream}: read from {self.url} failed: {exc}") from exc
        return [RawChunk(self.stream, time.time(), data)] if data else []

    def _arrived(self) -> bytes:
        """The bytes that have arrived, without waiting. A socket:// port's ``in_waiting`` only says whether
        any have (pyserial polls the socket: 0 or 1), so it reads them at once with no timeout."""
        waiting = self.port.in_waiting
        if not waiting or not self.url.startswith("socket://"):
            return self.port.read(waiting) if waiting else b""
        timeout, self.port.timeout = self.port.timeout, 0
        try:
            return self.port.read(SOCKET_READ_MAX)
        finally:
            self.port.timeout = timeout

    def write(self, data: bytes) -> None:
        if self.port is None:
            raise TransportError(f"{self.stream}: {self.url} is not open")
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"{self.stream}: write to {self.url} failed: {exc}") from exc

    def close(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            except (serial.SerialException, OSError):
                pass  # already gone
            self.port = None


IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)  # Linux; not exported by every Python
SO_RCVBUFFORCE_LINUX = 33  # not exported by Python


def open_can_bus(interface: str, channel: str, bitrate: int | None = None) -> can.BusABC:
    """A python-can bus; ``udp_multicast`` always with hop_limit=0 so frames never leave this host, and
    (Linux, IPv4) receiving only its own group: all groups share python-can's UDP port, and by default a
    socket gets every group any socket on the host joined, so two rigs on one host would mix."""
    kwargs: dict = {"interface": interface, "channel": channel}
    if interface == "udp_multicast":
        kwargs["hop_limit"] = 0
    elif bitrate is not None and interface not in ("virtual",):
        kwargs["bitrate"] = bitrate
    bus = can.Bus(**kwargs)
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None) or getattr(bus, "socket", None)
    if sys.platform == "linux" and sock is not None and sock.family == socket.AF_INET:
        sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
    if isinstance(sock, socket.socket):
        receive_buffer(sock, CAN_RECEIVE_BUFFER)
    return bus


def receive_buffer(sock: socket.socket, size: int) -> int:
    """Ask for a receive buffer of ``size`` bytes (past ``net.core.rmem_max`` where the process may: Linux's
    SO_RCVBUFFORCE needs CAP_NET_ADMIN); returns the bytes the kernel grants (it doubles the request for its
    bookkeeping, and caps a plain request at twice ``rmem_max``)."""
    force = getattr(socket, "SO_RCVBUFFORCE", SO_RCVBUFFORCE_LINUX if sys.platform == "linux" else None)
    try:
        sock.setsockopt(socket.SOL_SOCKET, force if force is not None else socket.SO_RCVBUF, size)
    except PermissionError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


class CanTransport(Transport):
    """A python-can bus as a transport of raw CAN chunks."""

    def __init__(self, interface: str, channel: str, stream: str, bitrate: int | None = None) -> None:
        self.interface, self.channel, self.bitrate, self.stream = interface, channel, bitrate, stream
        self.address = f"{CAN_SCHEME}://{interface}/{channel}"
        self.bus: can.BusABC | None = None

    def open(self) -> None:
        try:
            self.bus = open_can_bus(self.interface, self.channel, self.bitrate)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise TransportError(f"{self.stream}: cannot open CAN {self.interface}:{self.channel}: {exc}") from exc

    def read(self) -> list[RawChunk]:
        """The first message to arrive within ``POLL_S`` and every one already waiting behind it (at most
        :data:`CAN_READ_MAX`): a read a message would cost a thread wake-up each, six a sample at 1 kHz."""
        if self.bus is None:
            raise TransportError(f"{self.stream}: CAN {self.interface}:{self.channel} is not open")
        chunks: list[RawChunk] = []
        try:
            message = self.bus.recv(timeout=POLL_S)
            while message is not None:
                chunks.append(message_to_chunk(message, self.stream))
                message = self.bus.recv(timeout=0.0) if len(chunks) < CAN_READ_MAX else None
        except (can.CanError, OSError) as exc:
            raise TransportError(f"{self.stream}: CAN receive failed: {exc}") from exc
        return chunks

    def send(self, message: can.Message) -> None:
        if self.bus is None:
            raise TransportError(f"{self.stream}: CAN {self.interface}:{self.channel} is not open")
        try:
            self.bus.send(message)
        except (can.CanError, OSError) as exc:
            raise TransportError(f"{self.stream}: CAN send failed: {exc}") from exc

    def close(self) -> None:
        if self.bus is not None:
            self.bus.shutdown()
            self.bus = None


CAN_SCHEME = "can"


def open_transport(port: str | Mapping[str, Any], stream: str, baudrate: int = 115200) -> Transport:
    """The (not yet opened) transport of a port, named the way the config and ports.json name it.

    - a CAN port: a mapping ``{"interface": ..., "channel": ...[, "bitrate": N]}`` as python-can takes it
      (ports.json's form), or the URL ``can://INTERFACE/CHANNEL[?bitrate=N]``;
    - anything else is a pyserial URL (a device path, ``socket://``, ``rfc2217://``, ...) at ``baudrate``.
    """
    if isinstance(port, Mapping):
        bitrate = port.get("bitrate")
        return CanTransport(port["interface"], port["channel"], stream, None if bitrate is None else int(bitrate))
    parts = urlsplit(port)
    if parts.scheme == CAN_SCHEME:
        channel = parts.path.lstrip("/")
        if not parts.netloc or not channel:
            raise TransportError(f"{stream}: {port}: a CAN URL is can://INTERFACE/CHANNEL[?bitrate=N]")
        bitrate = parse_qs(parts.query).get("bitrate", [None])[0]
        try:
            return CanTransport(parts.netloc, channel, stream, None if bitrate is None else int(bitrate))
        except ValueError:
            raise TransportError(f"{stream}: {port}: bitrate must be a whole number") from None
    return SerialTransport(port, baudrate, stream)
