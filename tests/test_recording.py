"""The MCAP recording: round trip, CAN frames, events, a file cut short, and third-party readability."""

import pytest
from mcap.reader import make_reader

from drivers.codec import RawChunk, StreamEvent
from hil.recording.recorder import FORMAT, Recorder, read_recording


def _items():
    return [
        RawChunk("imu", 1700000000.123456789, b"\xfe\x81\xff\x55\x00\x01"),
        RawChunk("table", 1700000000.2, b"\xaa\x55" + bytes(range(30))),
        RawChunk("imu", 1700000000.3, bytes([1, 2, 3, 4, 5, 6, 7, 8]), arbitration_id=0x18F0_2A80, is_extended_id=True),
        StreamEvent("imu", 1700000000.4, "outage", "device unplugged"),
        RawChunk("imu", 1700000000.5, b""),
    ]


def _record(path, items, config="x"):
    rec = Recorder(path, config)
    for item in items:
        rec.write(item)
    rec.close()
    return path


def test_round_trip_keeps_order_bytes_and_nanosecond_times(tmp_path):
    path = _record(tmp_path / "r.mcap", _items(), "trial: {name: x}\n")
    back = read_recording(path)
    assert not back.truncated
    assert back.metadata["config"] == "trial: {name: x}\n" and back.metadata["format"] == FORMAT
    assert len(back.items) == 5
    for a, b in zip(_items(), back.items):
        assert type(a) is type(b)
        assert b.host_time == round(a.host_time * 1e9) / 1e9
        if isinstance(a, RawChunk):
            assert (a.stream, a.data, a.arbitration_id, a.is_extended_id) == (b.stream, b.data, b.arbitration_id, b.is_extended_id)
        else:
            assert (a.stream, a.event, a.detail) == (b.stream, b.event, b.detail)


def test_a_file_cut_anywhere_reads_up_to_its_last_whole_record(tmp_path):
    path = _record(tmp_path / "r.mcap", [RawChunk("imu", 1.0 + i, bytes([i]) * 40) for i in range(50)])
    data = path.read_bytes()
    counts = []
    for cut in range(len(data) // 2, len(data) - 1, 97):
        (tmp_path / "cut.mcap").write_bytes(data[:cut])
        back = read_recording(tmp_path / "cut.mcap")
        assert back.truncated
        assert [c.data for c in back.items] == [bytes([i]) * 40 for i in range(len(back.items))]
        counts.append(len(back.items))
    assert counts == sorted(counts) and counts[-1] >= 48


def test_other_tools_read_it_with_the_mcap_reader(tmp_path):
    path = _record(tmp_path / "r.mcap", _items())
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        topics = [channel.topic for _, channel, _ in reader.iter_messages()]
        summary = reader.get_summary()
    assert topics == ["imu", "table", "imu", "events", "imu"]
    assert summary.statistics.message_count == 5


def test_not_a_recording_is_a_clear_error(tmp_path):
    path = tmp_path / "x.mcap"
    path.write_bytes(b"hello world, not mcap")
    with pytest.raises(ValueError, match="not a turntable-hil recording"):
        read_recording(path)
