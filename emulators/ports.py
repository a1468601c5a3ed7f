"""The emulated devices' ports: a pseudo-terminal per serial device, a python-can bus for a CAN IMU.

Both offer the same small interface to the device writers: ``path`` (what clients open), ``write``,
``has_reader`` / ``accepting`` / ``flushed`` (what a UART's far end would show), ``drain``, and
``unplug`` / ``replug`` / ``close``.
"""

from __future__ import annotations

import fcntl
import os
import select
import struct
import termios
import threading
import time
import tty
from pathlib import Path

from drivers.transport import open_can_bus

WAIT_S = 0.1  # longest blocking step, so a stop request is seen promptly
PACKET_MODE = struct.pack("i", 1)  # TIOCPKT on the master: a flush of the reader's input is reported to it


class PtyPort:
    """One pseudo-terminal: the emulator writes the master side; clients open :attr:`path` (the slave).

    With ``link`` the port is published as that symbolic link to the slave, like a udev by-id name:
    :meth:`unplug` closes the master, as pulling a USB adapter removes its device (readers get an
    error, the link dangles), and :meth:`replug` opens a new pty and points the link at it, so a
    reader that reopens the link finds the device again, never another program's pty that took the
    old number. The link is replaced in one step, so a later emulator publishing the same link takes
    it over; :meth:`close` removes it only while it still points at this port's pty.
    """

    def __init__(self, link: Path | None = None) -> None:
        self.link = link
        self.inbox: bytearray | None = None  # a bytearray: what the reader writes is kept there (else dropped)
        self._reading = threading.Lock()  # the master's input is read by one thread at a time, and not once closed
        self._open()

    def _open(self) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no newline translation: bytes pass unchanged
        self.tty = os.ttyname(slave)
        os.close(slave)  # the slave stays valid while the master is open
        os.set_blocking(self.master, False)
        self.plugged = True
        fcntl.ioctl(self.master, termios.TIOCPKT, PACKET_MODE)
        self._flushed = False
        if self.link is not None:
            tmp = self.link.with_name(f"{self.link.name}.{os.getpid()}.new")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(self.tty)
            os.replace(tmp, self.link)

    @property
    def path(self) -> str:
        return str(self.link) if self.link is not None else self.tty

    def _events(self, timeout_ms: float, mask: int = select.POLLOUT) -> list[int]:
        """The master's poll events (a poll object per call: the writer thread and the drain may ask at once)."""
        poll = select.poll()
        poll.register(self.master, mask)
        return [events for _, events in poll.poll(timeout_ms)]

    def has_reader(self) -> bool:
        """True while some client holds the slave side open (the master reports no hang-up)."""
        return not any(events & select.POLLHUP for events in self._events(0))

    def accepting(self) -> bool:
        """True when a reader holds the port and its input queue has room: a UART's bytes would arrive."""
        return any(e & select.POLLOUT and not e & select.POLLHUP for e in self._events(0))

    def flushed(self) -> bool:
        """True once the reader has emptied its input (a serial library does as it opens the port, just after
        setting the line up): bytes written from then on reach it. Packet mode reports the flush to the master
        as a status byte (:meth:`take_input`)."""
        if not self._flushed:
            self.take_input()
        return self._flushed

    def take_input(self, wait_s: float = 0.0) -> None:
        """Read what the reader's side sent, waiting up to ``wait_s`` for it: its flushes (noted for :meth:`flushed`)
        and the bytes it wrote (kept in :attr:`inbox` when there is one, else dropped)."""
        readable = select.POLLIN | select.POLLPRI
        while any(e & readable for e in self._events(wait_s * 1000, readable)):
            wait_s = 0.0
            with self._reading:
                try:
                    packet = os.read(self.master, 4096) if self.plugged else b""
                except OSError:  # EIO: no reader holds the port
                    packet = b""
                if not packet:
                    return
                if packet[0] == termios.TIOCPKT_DATA:
                    if self.inbox is not None:
                        self.inbox += packet[1:]
                else:
                    self._flushed = self._flushed or (packet[0] & termios.TIOCPKT_FLUSHREAD) != 0

    def write(self, data: bytes, stop: threading.Event) -> bool:
        """Write all of ``data``, waiting while the kernel buffer is full; False if stopped first."""
        view = memoryview(data)
        while view:
            if stop.is_set():
                return False
            if not self._events(WAIT_S * 1000):
                continue
            try:
                view = view[os.write(self.master, view):]
            except BlockingIOError:
                continue
        return True

    def unread(self) -> int:
        """Bytes written but not yet read by the client (the slave's input queue)."""
        fd = os.open(self.tty, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0" * 4))[0]
        finally:
            os.close(fd)

    def drain(self, stop: threading.Event, timeout_s: float) -> bool:
        """Wait until the client has read everything or left (closing the master discards unread bytes).

        The queue must read empty on two checks in a row: bytes still in the kernel's flip buffer are
        not counted yet.
        """
        deadline = time.monotonic() + timeout_s
        empty = 0
        while self.plugged and self.has_reader() and empty < 2:
            empty = empty + 1 if self.unread() == 0 else 0
            if time.monotonic() > deadline or stop.wait(WAIT_S / 5):
                return False
        return True

    def unplug(self) -> None:
        """Close the master; clients then read end-of-file/EIO and the slave disappears."""
        with self._reading:
            if self.plugged:
                os.close(self.master)
                self.plugged = False

    def replug(self) -> None:
        self._open()

    def close(self) -> None:
        """Unplug for good: the link goes too, unless another emulator has taken it over."""
        self.unplug()
        if self.link is not None and self._owns_link():
            self.link.unlink(missing_ok=True)

    def _owns_link(self) -> bool:
        try:
            return os.readlink(self.link) == self.tty
        except OSError:
            return False


class CanPort:
    """A python-can bus the IMU sends on; "unplugged" it is silent."""

    def __init__(self, interface: str, channel: str) -> None:
        self.interface, self.channel = interface, channel
        self.bus = open_can_bus(interface, channel)
        self.plugged = True

    @property
    def path(self) -> dict[str, str]:
        return {"interface": self.interface, "channel": self.channel}

    def has_reader(self) -> bool:
        return True  # a bus does not know its listeners

    def accepting(self) -> bool:
        return True

    def flushed(self) -> bool:
        return True

    def write(self, messages: list, stop: threading.Event) -> bool:
        """Send one sample's messages; False if stopped first (a sample sent is always counted as written)."""
        if stop.is_set():
            return False
        for m in messages:
            self.bus.send(m)
        return True

    def drain(self, stop: threading.Event, timeout_s: float) -> bool:
        return True

    def unplug(self) -> None:
        self.plugged = False

    def replug(self) -> None:
        self.plugged = True

    def close(self) -> None:
        self.bus.shutdown()


def wait_for_readers(ports: list, stop: threading.Event, flush_s: float = 2.0) -> bool:
    """Wait until every port has a reader, then until each reader has emptied its input (at most ``flush_s``:
    a reader such as ``cat`` never does): a serial library flushes its input as it opens the port, and a frame
    written before that flush would be lost to it, however long the reader took to get there. False if
    stopped first."""
    while not all(p.has_reader() for p in ports):
        if stop.wait(WAIT_S / 5):
            return False
    deadline = time.monotonic() + flush_s
    while not all(p.flushed() for p in ports) and time.monotonic() < deadline:
        if stop.wait(0.005):
            return False
    return not stop.is_set()
