"""Serial sessions and the turntable command client over real pseudo-terminals (no mocks)."""

from __future__ import annotations

import os
import select
import socket
import threading
import time
import tty
from pathlib import Path

import pytest
from tests.helpers import Decoding

from drivers.acl import AclReply, LineFramer, frame_reply, parse_message
from drivers.acutrol_controller import AcutrolController
from drivers.kvh1750 import STATUS_ALL_VALID, Kvh1750Codec
from drivers.reader import DeviceReader, next_tick
from drivers.table_controller import InterlockError, LimitError, TableError
from drivers.transport import SerialTransport
from hil.config import LimitsConfig
from hil.samples import ImuSample


def test_readers_that_gather_read_on_one_grid_of_the_host_clock():
    """Two readers given the same gather time wake at the same instants, whenever their reads returned."""
    for now in (0.0, 0.004, 12.3456, 1e6 + 0.0071):
        wait = next_tick(now, 0.01)
        assert 0.0 < wait <= 0.01 + 1e-12
        assert abs(round((now + wait) / 0.01) * 0.01 - (now + wait)) < 1e-9  # on the grid
    assert next_tick(0.0, 0.01) == pytest.approx(0.01)  # on a tick: the next one, not this one


class Pty:
    """A pseudo-terminal whose slave is reached through a stable symlink, like a udev name."""

    def __init__(self, link: Path) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tmp = link.with_suffix(".new")
        tmp.symlink_to(os.ttyname(self.slave))
        os.replace(tmp, link)

    def unplug(self) -> None:
        os.close(self.master)
        os.close(self.slave)


def wait_for(condition, timeout=5.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def kvh_bytes(codec: Kvh1750Codec, indices) -> bytes:
    return b"".join(codec.encode(codec.from_sample(ImuSample(i, (1e-6 * i, 0.0, 0.0), (0.0, 0.0, 0.049),
                                                             status=STATUS_ALL_VALID))) for i in indices)


@pytest.fixture
def link(tmp_path):
    return tmp_path / "ttyIMU"


def test_session_taps_every_byte_and_decodes_frames_over_a_pty(link):
    pty = Pty(link)
    codec = Kvh1750Codec(rate_hz=200)
    sink = Decoding(codec)
    stream = b"\x00garbage" + kvh_bytes(codec, range(10)) + b"\xfe\x81"
    with DeviceReader(SerialTransport(str(link), 921600, "imu"), [sink]):
        os.write(pty.master, stream)
        wait_for(lambda: len(sink.samples) == 10 and sum(len(c.data) for c in sink.raw) == len(stream))
        assert b"".join(c.data for c in sink.raw) == stream
        assert all(c.stream == "imu" and c.host_time > 0 for c in sink.raw)
        assert [s.sync_index for s in sink.samples] == list(range(10))
        assert sink.samples[3].dtheta[0] == pytest.approx(3e-6)
        assert sink.counters.skipped_bytes == 8
    assert sink.stopped
    pty.unplug()


def test_session_survives_unplug_and_replug_and_counts_the_gap(link):
    pty = Pty(link)
    codec = Kvh1750Codec(rate_hz=200)
    sink = Decoding(codec)
    reader = DeviceReader(SerialTransport(str(link), 921600, "imu"), [sink], backoff_s=(0.02, 0.1)).start()
    try:
        os.write(pty.master, kvh_bytes(codec, range(0, 40)))
        wait_for(lambda: len(sink.samples) == 40)
        pty.unplug()
        wait_for(lambda: reader.outages == 1)
        time.sleep(0.15)  # a few failed reopen attempts while the device is away
        pty = Pty(link)
        wait_for(lambda: any(c.event == "reconnected" for c in sink.events))
        os.write(pty.master, kvh_bytes(codec, range(70, 100)))
        wait_for(lambda: len(sink.samples) == 70)
    finally:
        reader.stop()
        pty.unplug()
    indices = [s.sync_index for s in sink.samples]
    assert indices == list(range(40)) + list(range(70, 100))
    assert reader.outages == 1
    assert (sink.counters.gaps, sink.counters.missing) == (1, 30)
    assert reader.down is None and sink.events[0].detail.startswith("imu: read from")


class FakeTable:
    """The far end of an Acutrol's command port: answers every message with a framed reply and records
    what it received."""

    def __init__(self, link: Path, interlocks: str = "Close", obeys_off: bool = True) -> None:
        self.pty = Pty(link)
        self.interlocks = interlocks
        self.obeys_off = obeys_off
        self.mode = "Position"
        self.lines: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        framer = LineFramer()
        while not self._stop.is_set():
            ready, _, _ = select.select([self.pty.master], [], [], 0.02)
            if not ready:
                continue
            for line in framer.feed(os.read(self.pty.master, 4096)):
                self.lines.append(line.decode())
                answers = []
                for command in parse_message(line):
                    if command.path == "Mode:Off" and self.obeys_off:
                        self.mode = "Off"
                    answers.append({"*IDN?": "Emulated table", ":Interlock?": self.interlocks,
                                    ":Mode?": self.mode}.get(command.header))
                text = ";".join(a for a in answers if a is not None)
                os.write(self.pty.master, frame_reply(AclReply(text)))

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.pty.unplug()


@pytest.fixture
def table(tmp_path):
    fake = FakeTable(tmp_path / "ttyTABLE")
    yield fake
    fake.close()


LIMITS = LimitsConfig(position_min_deg=(-170, -60, -170), position_max_deg=(170, 60, 170),
                      rate_dps=(30, 20, 40), accel_dps2=(50, 50, 50))


def test_demand_beyond_a_limit_raises_and_nothing_is_written(table):
    client = AcutrolController(table_link(table), LIMITS).open()
    with pytest.raises(LimitError, match=r"position 95 deg on the middle axis is outside .*\[-60, 60\]"):
        client.demand_position("middle", 95.0)
    with pytest.raises(LimitError, match="rate 25 deg/s on the middle axis exceeds the configured limit 20"):
        client.demand_rate("middle", -25.0)
    client.demand_position("inner", 10.0)
    with pytest.raises(LimitError, match="peak acceleration"):
        client.demand_oscillator("inner", 5.0, 1.0, 0.0)  # 5 deg at 1 Hz: 197 deg/s^2
    time.sleep(0.1)
    assert table.lines == [":Demand:Position 1,10"]
    client.close()
    assert table.lines[-2:] == [":Mode:Off 3;:Mode:Off 2;:Mode:Off 1", ":Mode? 3;:Mode? 2;:Mode? 1"]


def table_link(table: FakeTable) -> str:
    return os.ttyname(table.pty.slave)


def test_motion_needs_closed_interlocks(tmp_path):
    table = FakeTable(tmp_path / "ttyTABLE", interlocks="Open")
    try:
        with AcutrolController(table_link(table), LIMITS) as client:
            with pytest.raises(InterlockError, match="interlocks of the outer axis are open"):
                client.set_mode("outer", "position")
        assert table.lines == [":Interlock? 3", ":Mode:Off 3;:Mode:Off 2;:Mode:Off 1", ":Mode? 3;:Mode? 2;:Mode? 1"]
    finally:
        table.close()


def test_a_table_that_does_not_confirm_off_is_reported(tmp_path):
    table = FakeTable(tmp_path / "ttyTABLE", obeys_off=False)
    try:
        client = AcutrolController(table_link(table), LIMITS).open()
        with pytest.raises(TableError, match="not all off"):
            client.close()
        assert table.lines == [":Mode:Off 3;:Mode:Off 2;:Mode:Off 1", ":Mode? 3;:Mode? 2;:Mode? 1"] and client.port is None
    finally:
        table.close()


def test_ctrl_c_inside_a_session_still_switches_the_table_off(table):
    with pytest.raises(KeyboardInterrupt):
        with AcutrolController(table_link(table), LIMITS) as client:
            assert client.identify() == "Emulated table"
            client.apply_limits()
            client.set_mode("inner", "synthesis")
            raise KeyboardInterrupt
    assert table.lines[0] == "*IDN?"
    assert (":Limit:Lowposition Rate,2,-60;:Limit:Highposition Rate,2,60;:Limit:Rate Rate,2,20;"
            ":Limit:Acceleration Rate,2,50") in table.lines
    assert table.lines[-4:] == [":Interlock? 1", ":Mode:Synthesis 1", ":Mode:Off 3;:Mode:Off 2;:Mode:Off 1", ":Mode? 3;:Mode? 2;:Mode? 1"]


def test_a_second_reader_cannot_open_a_port_already_in_use():
    import os
    import tty

    from drivers.transport import SerialTransport, TransportError

    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    first, second = SerialTransport(path, 115200, "imu"), SerialTransport(path, 115200, "imu")
    try:
        first.open()
        with pytest.raises(TransportError, match="cannot open"):
            second.open()
    finally:
        first.close()
        os.close(slave)
        os.close(master)


def test_a_reused_pty_number_is_not_reopened():
    import os
    import tty

    from drivers.transport import SerialTransport, TransportError

    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    transport = SerialTransport(path, 115200, "table")
    transport.open()
    transport.close()
    os.close(slave)
    os.close(master)  # the device goes; another program gets the same number a little later
    time.sleep(0.05)  # creation times come from the kernel's coarse clock
    held = [os.openpty() for _ in range(4)]
    try:
        if path not in {os.ttyname(s) for _, s in held}:
            pytest.skip("the pty number was not handed out again")
        with pytest.raises(TransportError, match="another program"):
            transport.open()
    finally:
        for m, s in held:
            os.close(s)
            os.close(m)


def test_a_socket_port_read_takes_every_byte_that_has_arrived():
    """pyserial's socket:// ``in_waiting`` is only 0 or 1: a read must still take the whole backlog."""
    server = socket.create_server(("127.0.0.1", 0))
    transport = SerialTransport(f"socket://127.0.0.1:{server.getsockname()[1]}", 115200, "imu")
    transport.open()
    peer, _ = server.accept()
    try:
        payload = bytes(range(256)) * 40
        peer.sendall(payload)  # on the loopback the bytes are in the receiving socket once sendall returns
        chunks = transport.read()
        assert len(chunks) == 1 and chunks[0].data == payload, [len(c.data) for c in chunks]
    finally:
        transport.close()
        peer.close()
        server.close()
