"""The emulated table's ``acl`` command port: a loopback TCP server answering each line through the servo."""

from __future__ import annotations

import selectors
import socket
import sys
import threading
from collections import Counter

from drivers.acl import AclCodec, AclCommand, AclError, AclReply, LineFramer
from emulators.servo import Servo

POLL_S = 0.05


class AclServer:
    """Serves ``acl`` on 127.0.0.1 (an ephemeral port unless given), any number of clients, one reply a line.

    :attr:`received` counts the commands by header; every ``:Mode`` command is also logged on stderr
    (the emulator's log), so a test or an operator sees that the table was turned off.
    """

    def __init__(self, servo: Servo, port: int = 0) -> None:
        self.servo = servo
        self.codec = AclCodec()
        self.received: Counter[str] = Counter()
        self.modes_off = 0  # ``:Mode ALL,Off`` commands received
        self._listener = socket.create_server(("127.0.0.1", port))
        self._listener.setblocking(False)
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._listener, selectors.EVENT_READ)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="acl-server", daemon=True)
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
                    self._serve(key.fileobj, key.data)

    def _accept(self) -> None:
        try:
            conn, _ = self._listener.accept()
        except BlockingIOError:
            return
        conn.setblocking(True)
        conn.settimeout(1.0)
        self._selector.register(conn, selectors.EVENT_READ, LineFramer())

    def _serve(self, conn: socket.socket, framer: LineFramer) -> None:
        try:
            data = conn.recv(4096)
        except OSError:
            data = b""
        if not data:
            self._selector.unregister(conn)
            conn.close()
            return
        for line in framer.feed(data):
            if not line.strip():
                continue
            try:
                command = self.codec.parse_command(line)
            except AclError as exc:
                reply = AclReply(str(exc), exc.code)
            else:
                reply = self.servo.handle(command)
                self._note(command, reply)
            try:
                conn.sendall(self.codec.format_reply(reply))
            except OSError:
                break

    def _note(self, command: AclCommand, reply: AclReply) -> None:
        self.received[command.header] += 1
        if command.header == ":Mode":
            self.modes_off += command.args == ("ALL", "Off") and reply.ok
            status = "OK" if reply.ok else f"?{reply.error} {reply.text}"
            print(f"acl: {command.header} {','.join(map(str, command.args))} -> {status}", file=sys.stderr, flush=True)

    def close(self) -> None:
        """Stop serving, close every connection and release the port."""
        self._stop.set()
        self._thread.join(2.0)
        for key in list(self._selector.get_map().values()):
            key.fileobj.close()
        self._selector.close()
