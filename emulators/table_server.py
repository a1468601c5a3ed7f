"""The emulated table's command port: a loopback TCP server (:class:`TableServer`) or, in the caller's process,
a port object (:class:`ServoPort`), each handing the bytes to the emulated table of the configured controller.

An emulated table (:mod:`emulators.acutrol_table`, :mod:`emulators.aerosmith_table`, or a plug-in's) takes
the bytes a client writes and returns the bytes it answers (:meth:`feed`), translating its dialect to the
servo's methods; it counts the commands by name (``received``), the Offs that reached every axis
(``offs``), keeps every message with its error code (``log``; with ``log=True`` also on stderr, the
emulator's log) and says the axes' modes (:meth:`modes`).
"""

from __future__ import annotations

import selectors
import socket
import threading

from drivers.controllers import controller_options
from drivers.registry import TABLE_CONTROLLERS
from emulators.servo import Servo
from hil.config import ConfigError

POLL_S = 0.05


def emulated_table(cfg, servo: Servo, log: bool = False):
    """The emulated table of ``turntable.controller`` (found by the controller's name), on ``servo``, with the
    controller's options."""
    table = TABLE_CONTROLLERS.emulated(cfg.turntable.controller)
    if table is None:
        raise ConfigError(f"turntable.controller: {cfg.turntable.controller!r} has no emulated table; "
                          "with it the table is a real one (turntable.source: serial)")
    return table(servo, controller_options(cfg.turntable), log=log)


class ServoPort:
    """The emulated table's command port in the caller's process, for
    :meth:`drivers.table_controller.TableController.open`: the bytes written are answered as the command
    server answers them, and read back with :meth:`read` or :meth:`read_until`."""

    def __init__(self, table) -> None:
        self.table = table
        self._replies = bytearray()

    def reset_input_buffer(self) -> None:
        self._replies.clear()

    def write(self, data: bytes) -> int:
        self._replies += self.table.feed(data)
        return len(data)

    def read(self, size: int = 1) -> bytes:
        out = bytes(self._replies[:size])
        del self._replies[:size]
        return out

    def read_until(self, expected: bytes = b"\n") -> bytes:
        end = self._replies.find(expected)
        return self.read(len(self._replies) if end < 0 else end + len(expected))

    def close(self) -> None:
        self._replies.clear()


class TableServer:
    """Serves an emulated table on 127.0.0.1 (an ephemeral port unless given); a client that disconnects
    leaves no partial line behind (the table's :meth:`reset`)."""

    def __init__(self, table, port: int = 0) -> None:
        self.responder = table
        self._listener = socket.create_server(("127.0.0.1", port))
        self._listener.setblocking(False)
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._listener, selectors.EVENT_READ)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="table-server", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self._listener.getsockname()[1]}"

    def _run(self) -> None:
        while not self._stop.is_set():
            for key, _ in self._selector.select(POLL_S):
                if key.fileobj is self._listener:
                    self._accept()
                else:
                    self._serve(key.fileobj)

    def _accept(self) -> None:
        try:
            conn, _ = self._listener.accept()
        except BlockingIOError:
            return
        conn.setblocking(True)
        conn.settimeout(1.0)
        self._selector.register(conn, selectors.EVENT_READ)

    def _serve(self, conn: socket.socket) -> None:
        try:
            data = conn.recv(4096)
        except OSError:
            data = b""
        if not data:
            self._selector.unregister(conn)
            conn.close()
            self.responder.reset()
            return
        reply = self.responder.feed(data)
        if reply:
            try:
                conn.sendall(reply)
            except OSError:
                pass

    def close(self) -> None:
        """Stop serving, close every connection and release the port."""
        self._stop.set()
        self._thread.join(2.0)
        for key in list(self._selector.get_map().values()):
            key.fileobj.close()
        self._selector.close()
