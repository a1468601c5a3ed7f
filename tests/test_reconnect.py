"""A reader on an emulated device's stable link: it reconnects to a restarted device, whatever the link
does meanwhile, and never reads another program's pty left at the old number (real ptys, no mocks)."""

from __future__ import annotations

import os
import select
import termios
import threading
import time

import pytest
import serial

from drivers.codec import RawChunk, StreamEvent
from drivers.reader import DeviceReader
from drivers.tap import RawListener
from drivers.transport import SerialTransport, TransportError
from emulators.ports import PtyPort

STOP = threading.Event()  # never set: PtyPort.write's stop request


class Sink(RawListener):
    def __init__(self) -> None:
        self.chunks: list[RawChunk] = []
        self.events: list[StreamEvent] = []

    def on_raw(self, chunk: RawChunk) -> None:
        self.chunks.append(chunk)

    def on_event(self, event: StreamEvent) -> None:
        self.events.append(event)

    @property
    def data(self) -> bytes:
        return b"".join(c.data for c in self.chunks)

    @property
    def kinds(self) -> list[str]:
        return [e.event for e in self.events]


class CountingTransport(SerialTransport):
    """Counts its open attempts, failed or not."""

    opens = 0

    def open(self) -> None:
        self.opens += 1
        super().open()


def wait_for(condition, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)


@pytest.fixture(params=["link", "link to the link"])
def device(tmp_path, request):
    """A PtyPort on a stable link with a reader on the link (or on a link to it, as a lab's own name for an
    emulator's) and its sink; the port can be replaced."""
    link = tmp_path / "imu"
    state = {"port": PtyPort(link)}
    url = link
    if request.param == "link to the link":
        url = tmp_path / "lab-imu"
        url.symlink_to(link.name)
    sink = Sink()
    transport = CountingTransport(str(url), 921600, "imu")
    reader = DeviceReader(transport, [sink], backoff_s=(0.005, 0.02)).start()
    state["port"].write(b"before;", STOP)
    wait_for(lambda: sink.data == b"before;")
    yield link, state, sink, reader
    reader.stop()
    state["port"].close()


def test_a_restarted_device_on_the_same_link_is_read_again(device):
    link, state, sink, reader = device
    state["port"].unplug()  # the emulator is killed: its pty's master closes
    wait_for(lambda: sink.kinds == ["outage"])
    state["port"] = PtyPort(link)  # the restarted emulator: a new pty, the link re-pointed at it
    wait_for(lambda: sink.kinds == ["outage", "reconnected"])
    state["port"].write(b"after;", STOP)
    wait_for(lambda: sink.data == b"before;after;")
    assert all(e.stream == "imu" for e in sink.events)
    assert "imu: read from" in sink.events[0].detail and reader.outages == 1 and reader.down is None


def test_the_reader_keeps_retrying_while_the_link_dangles(device):
    link, state, sink, reader = device
    state["port"].unplug()
    wait_for(lambda: sink.kinds == ["outage"])
    opens = reader.transport.opens
    # the link points at a pty that is gone (or, on a busy host, that another program now has)
    wait_for(lambda: reader.transport.opens >= opens + 5)
    assert sink.kinds == ["outage"]
    link.unlink()  # gone entirely for a while
    wait_for(lambda: reader.transport.opens >= opens + 10)
    assert sink.kinds == ["outage"]
    state["port"] = PtyPort(link)
    wait_for(lambda: sink.kinds == ["outage", "reconnected"])
    state["port"].write(b"after;", STOP)
    wait_for(lambda: sink.data == b"before;after;")


def take_pty_number(tty: str) -> list[int]:
    """The masters of ptys opened until one has the number ``tty`` had (numbers are handed out lowest first),
    as another program's terminal would get it, its slave closed; skips the test when some other program
    took the number first."""
    masters: list[int] = []
    name = ""
    while name != tty and len(masters) < 64:
        master, slave = os.openpty()
        masters.append(master)
        name = os.ttyname(slave)
        os.close(slave)  # the pty lives on while its master is open
    if name != tty:
        for master in masters:
            os.close(master)
        pytest.skip(f"another program took {tty}")
    return masters


def test_another_programs_pty_at_the_dangling_link_is_never_read(device):
    link, state, sink, reader = device
    old = state["port"].tty
    time.sleep(0.05)  # pty creation times come from the kernel's coarse clock: the next one must differ
    state["port"].unplug()
    wait_for(lambda: sink.kinds == ["outage"])  # the reader has released the pty: its number is free
    masters = take_pty_number(old)
    try:
        assert os.path.realpath(link) == old and link.exists()  # the stale link now leads to that terminal
        opens = reader.transport.opens
        wait_for(lambda: reader.transport.opens >= opens + 5)
        assert "another program's pseudo-terminal" in reader.down
        assert sink.kinds == ["outage"]
        poll = select.poll()
        poll.register(masters[-1], select.POLLOUT)
        assert all(events & select.POLLHUP for _, events in poll.poll(0))  # nobody holds that terminal
        state["port"] = PtyPort(link)  # the device returns on a new pty
        wait_for(lambda: sink.kinds == ["outage", "reconnected"])
        state["port"].write(b"after;", STOP)
        wait_for(lambda: sink.data == b"before;after;")
    finally:
        for master in masters:
            os.close(master)


def test_a_pty_that_hangs_up_while_it_is_opened_is_a_failed_open(monkeypatch):
    """pyserial's open lets termios.error out when the pty hangs up during its set-up (its input flush
    fails with EIO): it must reach the reader as a failed open, which it retries, not end its thread."""
    def hangs_up(*args, **kwargs):
        raise termios.error(5, "Input/output error")

    monkeypatch.setattr(serial, "serial_for_url", hangs_up)
    with pytest.raises(TransportError, match=r"imu: cannot open /dev/ttyX: input/output error$"):
        SerialTransport("/dev/ttyX", 921600, "imu").open()
