"""The emulated table's ``acl`` command port: a loopback TCP server (:class:`AclServer`) or, in the caller's
process, a port object (:class:`ServoPort`), each answering every line through the servo (:class:`AclResponder`)."""

from __future__ import annotations

import selectors
import socket
import sys
import threading
from collections import Counter

from drivers.acl import AclCodec, AclCommand, AclError, AclReply, LineFramer
from emulators.servo import Servo

POLL_S = 0.05


class AclResponder:
    """The servo's reply line to each command line; :attr:`received` counts the commands by header,
    :attr:`modes_off` the accepted ``:Mode ALL,Off``. With ``log`` every ``:Mode`` command is also logged
    on stderr (the emulator's log), so a test or an operator sees that the table was turned off."""

    def __init__(self, servo: Servo, log: bool = False) -> None:
        self.servo = servo
        self.log = log
        self.codec = AclCodec()
        self.received: Counter[str] = Counter()
        self.modes_off = 0

    def answer(self, line: bytes) -> bytes:
        """The reply, with its line end, to one line (without its line end)."""
        try:
            command = self.codec.parse_command(line)
        except AclError as exc:
            reply = AclReply(str(exc), exc.code)
        else:
            reply = self.servo.handle(command)
            self._note(command, reply)
        return self.codec.format_reply(reply)

    def _note(self, command: AclCommand, reply: AclReply) -> None:
        self.received[command.header] += 1
        if command.header == ":Mode":
            self.modes_off += command.args == ("ALL", "Off") and reply.ok
            if self.log:
                status = "OK" if reply.ok else f"?{reply.error} {reply.text}"
                print(f"acl: {command.header} {','.join(map(str, command.args))} -> {status}", file=sys.stderr,
                      flush=True)


class ServoPort:
    """The emulated table's command port in the caller's process, for
    :meth:`drivers.table_client.TableCommandClient.open`: the bytes written are answered line by line
    as the command server answers them, and read back with :meth:`read_until`."""

    def __init__(self, servo: Servo) -> None:
        self.responder = AclResponder(servo)
        self._framer = LineFramer()
        self._replies = bytearray()

    def reset_input_buffer(self) -> None:
        self._replies.clear()

    def write(self, data: bytes) -> int:
        for line in self._framer.feed(data):
            if line.strip():
                self._replies += self.responder.answer(line)
        return len(data)

    def read_until(self, expected: bytes = b"\n") -> bytes:
        end = self._replies.find(expected)
        size = len(self._replies) if end < 0 else end + len(expected)
        out = bytes(self._replies[:size])
        del self._replies[:size]
        return out

    def close(self) -> None:
        self._replies.clear()


class AclServer:
    """Serves ``acl`` on 127.0.0.1 (an ephemeral port unless given), any number of clients, one reply a line
    (:attr:`responder` counts and logs the commands)."""

    def __init__(self, servo: Servo, port: int = 0) -> None:
        self.responder = AclResponder(servo, log=True)
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
                conn.sendall(self.responder.answer(line))
            except OSError:
                break

    def close(self) -> None:
        """Stop serving, close every connection and release the port."""
        self._stop.set()
        self._thread.join(2.0)
        for key in list(self._selector.get_map().values()):
            key.fileobj.close()
        self._selector.close()
