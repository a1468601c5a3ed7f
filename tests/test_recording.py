"""The MCAP recording: round trip, CAN frames, events, a file cut short, streamed reading, and third-party
readability."""

import pytest
from mcap.reader import make_reader

from drivers.codec import RawChunk, StreamEvent
from hil.recording.recorder import FORMAT, Recorder, RecordingReader, read_recording


def _items():
    return [
        RawChunk("imu", 1700000000.123456789, b"\xfe\x81\xff\x55\x00\x01"),
        RawChunk("table", 1700000000.2, b"\xaa\x55" + bytes(range(30))),
        RawChunk("imu", 1700000000.3, bytes([1, 2, 3, 4, 5, 6, 7, 8]), arbitration_id=0x18F0_2A80, is_extended_id=True),
        StreamEvent("imu", 1700000000.4, "outage", "device unplugged"),
        RawChunk("imu", 1700000000.5, b""),
    ]


def _record(path, items, config="x", ended=None):
    rec = Recorder(path, config)
    for item in items:
        rec.write(item)
    rec.close(ended)
    assert rec.backlog == 0
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


def test_the_reader_has_the_metadata_at_once_then_the_items_of_the_whole_read_one_by_one(tmp_path):
    path = _record(tmp_path / "r.mcap", _items(), "trial: {name: x}\n", ended="early: devices lost")
    whole = read_recording(path)
    with RecordingReader(path) as reader:
        assert reader.metadata == whole.metadata and reader.metadata["config"] == "trial: {name: x}\n"
        with pytest.raises(RuntimeError, match="once every item has been read"):
            reader.ended  # noqa: B018 - the trial_end record comes last
        items = iter(reader)
        assert next(items) == whole.items[0]
        with pytest.raises(RuntimeError):
            reader.truncated  # noqa: B018 - not before the end
        assert [whole.items[0], *items] == whole.items
        assert not reader.truncated and reader.ended == "early: devices lost" == whole.ended
        with pytest.raises(RuntimeError, match="read once"):
            list(reader)


def test_a_file_cut_short_streams_up_to_the_cut_and_is_truncated_after_the_last_item(tmp_path):
    path = _record(tmp_path / "r.mcap", [RawChunk("imu", 1.0 + i, bytes([i]) * 40) for i in range(50)],
                   ended="completed")
    data = path.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) * 3 // 4])
    reader = RecordingReader(tmp_path / "cut.mcap")
    items = list(reader)
    assert 30 < len(items) < 50 and [c.data for c in items] == [bytes([i]) * 40 for i in range(len(items))]
    assert reader.truncated and reader.ended is None
    assert items == read_recording(tmp_path / "cut.mcap").items


def test_a_recording_without_items_ends_at_once(tmp_path):
    path = _record(tmp_path / "r.mcap", [], ended="completed")
    reader = RecordingReader(path)
    assert list(reader) == [] and not reader.truncated and reader.ended == "completed"


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
    with pytest.raises(ValueError, match=r"x.mcap: not a turntable-hil recording \(not a valid MCAP file"):
        RecordingReader(path)
    (tmp_path / "short.mcap").write_bytes(_record(tmp_path / "r.mcap", _items()).read_bytes()[:30])
    with pytest.raises(ValueError, match=r"short.mcap: not a turntable-hil recording \(the file ends before the trial"):
        RecordingReader(tmp_path / "short.mcap")


def test_an_mcap_file_of_another_kind_is_not_a_recording(tmp_path):
    from mcap.writer import Writer

    for name, metadata in (("other.mcap", {}), ("format.mcap", {"trial": {"format": "other/1"}})):
        with open(tmp_path / name, "wb") as fh:
            writer = Writer(fh)
            writer.start()
            writer.add_message(writer.register_channel("x", "json", 0), log_time=1, data=b"{}", publish_time=1)
            for key, value in metadata.items():
                writer.add_metadata(key, value)
            writer.finish()
    with pytest.raises(ValueError, match=r"other.mcap: not a turntable-hil recording \(format None\)"):
        RecordingReader(tmp_path / "other.mcap")
    with pytest.raises(ValueError, match=r"format.mcap: not a turntable-hil recording \(format 'other/1'\)"):
        read_recording(tmp_path / "format.mcap")


def test_messages_before_the_trial_metadata_are_read_too(tmp_path):
    from mcap.writer import Writer

    with open(tmp_path / "late.mcap", "wb") as fh:
        writer = Writer(fh)
        writer.start()
        writer.add_message(writer.register_channel("imu", "application/octet-stream", 0), log_time=10**9,
                           data=b"\x01\x02", publish_time=10**9)
        writer.add_metadata("trial", {"format": FORMAT, "config": "x"})
        writer.finish()
    reader = RecordingReader(tmp_path / "late.mcap")
    assert reader.metadata["config"] == "x" and list(reader) == [RawChunk("imu", 1.0, b"\x01\x02")]
    assert not reader.truncated and reader.ended is None


def test_a_read_error_past_the_metadata_is_one_line_naming_the_file(tmp_path, monkeypatch):
    """An I/O error in the middle of a recording (a failing disk) is an input error, not a traceback."""
    from hil.recording.csv_input import DataError

    path = tmp_path / "r.mcap"
    rec = Recorder(path, "trial: {}\n")
    rec.write(RawChunk("imu", 1.0, b"abc"))
    rec.close("completed")
    reader = RecordingReader(path)

    def failing(record):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(reader, "_take", failing)
    with pytest.raises(DataError, match=r"r\.mcap: cannot read: Input/output error"):
        list(reader)
