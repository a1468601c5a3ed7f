"""The trial recording: every raw byte chunk and CAN frame as received, in an MCAP file.

Format (MCAP, https://mcap.dev; readable by any MCAP tool):

- metadata record ``trial`` at the start: ``config`` (the trial YAML as given), ``version`` (this
  package's version), ``format`` (``turntable-hil/1``), ``duration_s`` (the trial length the live
  run used, empty when open-ended), ``time_scale`` (the emulator's speed, 1 for real devices, empty for as fast as possible);
- metadata record ``record`` after it: the trial's record as it starts (result.json's ``record`` but for
  ``ended_utc``: the unit, operator, station, software version and commit, config digest, ``started_utc``,
  host, ports as JSON, controller; "" for none);
- one channel per stream (``imu``, ``table``, ...), schemaless; its ``message_encoding`` says what a
  message holds: ``application/octet-stream`` (bytes exactly as read from a serial port) or
  ``turntable-hil/can-frame`` (4-byte big-endian arbitration id, 1 flag byte with bit 0 = extended
  id, then the payload);
- metadata record ``trial_end`` at the end, ``ended``: how the live trial ended (``completed``,
  ``early: <reason>``, ``interrupted: <signal>``), and ``ended_utc``; absent in a file cut short;
- channel ``events``, JSON messages ``{"stream": .., "event": "outage" | "reconnected", "detail": ..}``;
- ``log_time`` is the host receive time in integer nanoseconds (the pipeline works on that rounded
  time, so a replay sees exactly what the live run saw); ``sequence`` is the global arrival order.

Messages are written unchunked and the file is flushed every ``flush_s`` (0.1 s), so a killed
process loses at most that much. :class:`RecordingReader` reads a recording front to back with the
non-seeking reader, one item at a time (a 24 h trial replays in constant memory), and a file cut short
to its last whole record; :func:`read_recording` collects its items in a list.
"""

from __future__ import annotations

import json
import queue
import struct
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from mcap.exceptions import EndOfFile, McapError
from mcap.records import Channel, Message, Metadata
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer

from drivers.codec import RawChunk, StreamEvent
from hil import package_version
from hil.recording.csv_input import DataError
from hil.vocabulary import StreamEventKind

FORMAT = "turntable-hil/1"
BYTES = "application/octet-stream"
CAN_FRAME = "turntable-hil/can-frame"
EVENTS = "events"
_CAN_HEADER = struct.Struct(">IB")


def to_ns(host_time: float) -> int:
    return round(host_time * 1e9)


def encode_chunk(chunk: RawChunk) -> bytes:
    if chunk.arbitration_id is None:
        return chunk.data
    return _CAN_HEADER.pack(chunk.arbitration_id, int(chunk.is_extended_id)) + chunk.data


def decode_chunk(stream: str, encoding: str, log_time: int, data: bytes) -> RawChunk:
    host_time = log_time / 1e9
    if encoding == CAN_FRAME:
        arbitration_id, flags = _CAN_HEADER.unpack_from(data)
        return RawChunk(stream, host_time, data[_CAN_HEADER.size :], arbitration_id, bool(flags & 1))
    return RawChunk(stream, host_time, data)


class Recorder:
    """Appends chunks and events to an MCAP file from any thread; a writer thread does the disk work.

    :meth:`write` never blocks and never drops (an unbounded queue); the writer thread wakes every
    ``flush_s``, writes what is queued and flushes (one wake-up per interval, not one per chunk).
    :meth:`close` drains the queue and writes the MCAP summary.
    """

    def __init__(self, path: str | Path, config_text: str, flush_s: float = 0.1,
                 duration: float | None = None, time_scale: float | None = 1.0,
                 record: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")  # noqa: SIM115 - owned by the writer thread until close()
        # no message index: it would grow in memory for the whole trial (readers here read in order)
        self._writer = Writer(self._file, compression=CompressionType.NONE, use_chunking=False,
                              index_types=IndexType.NONE)
        self._writer.start(profile="", library=f"turntable-hil/{package_version()}")
        self._writer.add_metadata("trial", {"config": config_text, "version": package_version(), "format": FORMAT,
                                            "duration_s": "" if duration is None else repr(duration),
                                            "time_scale": "" if time_scale is None else repr(time_scale)})
        if record is not None:  # who, which unit, which software, when: strings, "" for none, JSON for a block
            self._writer.add_metadata("record", {key: "" if value is None else value if isinstance(value, str)
                                                 else json.dumps(value) for key, value in record.items()})
        self._channels: dict[tuple[str, str], int] = {}
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._flush_s = flush_s
        self._closing = threading.Event()
        self._sequence = 0
        self.messages = 0
        self.bytes = 0
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()

    def write(self, item: RawChunk | StreamEvent) -> None:
        """Queue one chunk or event for the file (thread-safe, constant time)."""
        self._queue.put(item)

    @property
    def backlog(self) -> int:
        """Items queued and not yet written (approximately: the writer thread takes them meanwhile); a
        producer faster than the disk waits on it to stay in bounded memory."""
        return self._queue.qsize()

    def close(self, ended: str | None = None) -> None:
        """Write what is queued, then ``ended`` (how the trial ended) and the MCAP summary."""
        self._queue.put(None)
        self._closing.set()
        self._thread.join()
        if ended is not None:
            ended_utc = datetime.now(timezone.utc).isoformat(timespec="seconds")
            self._writer.add_metadata("trial_end", {"ended": ended, "ended_utc": ended_utc})
        self._writer.finish()
        self._file.close()

    def discard(self) -> None:
        """Close and remove the file: a trial that never started leaves no recording to be taken for one."""
        self.close()
        self.path.unlink(missing_ok=True)

    def _run(self) -> None:
        """Write what is queued, then flush; at least one flush every ``flush_s``; None ends it."""
        while True:
            for item in self._queued():
                if item is None:
                    self._file.flush()
                    return
                self._add(item)
            self._file.flush()

    def _queued(self) -> Iterator[RawChunk | StreamEvent | None]:
        """Everything queued after ``flush_s`` (or at once when closing)."""
        self._closing.wait(self._flush_s)
        while True:
            try:
                yield self._queue.get_nowait()
            except queue.Empty:
                return

    def _add(self, item: RawChunk | StreamEvent) -> None:
        if isinstance(item, StreamEvent):
            channel = self._channel(EVENTS, "json")
            data = json.dumps({"stream": item.stream, "event": item.event, "detail": item.detail}).encode()
        else:
            channel = self._channel(item.stream, BYTES if item.arbitration_id is None else CAN_FRAME)
            data = encode_chunk(item)
        t = to_ns(item.host_time)
        self._writer.add_message(channel, log_time=t, data=data, publish_time=t, sequence=self._sequence)
        self._sequence += 1
        self.messages += 1
        self.bytes += len(data)

    def _channel(self, topic: str, encoding: str) -> int:
        key = (topic, encoding)
        if key not in self._channels:
            self._channels[key] = self._writer.register_channel(topic, encoding, schema_id=0)
        return self._channels[key]


@dataclass
class Recording:
    """What a recording holds, read whole: the trial metadata and the items in arrival order."""

    metadata: dict[str, str]
    items: list[RawChunk | StreamEvent]
    truncated: bool  # the file ended inside a record (the process was killed)
    ended: str | None = None  # how the live trial ended, when the recorder was closed

    def __iter__(self) -> Iterator[RawChunk | StreamEvent]:
        return iter(self.items)


def read_start_record(path: str | Path) -> dict[str, str] | None:
    """The ``record`` metadata a Recorder wrote at the start of the recording ``path`` (strings, "" for none);
    None when it has none (an older recording, or one cut before it)."""
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Message):
                    return None  # the metadata comes before any message
                if isinstance(record, Metadata) and record.name == "record":
                    return dict(record.metadata)
    except (OSError, McapError, EOFError, struct.error, ValueError):
        return None
    return None


class RecordingReader:
    """A recording read front to back in constant memory: the trial metadata on opening, then the items one
    by one in file order (iterate once); :attr:`truncated` and :attr:`ended` are known when the iteration
    has finished. Raises ValueError on opening if the file is not a recording; a file cut short ends the
    iteration at its last whole record. Closes the file at the end of the iteration, or on :meth:`close`.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = path
        self.metadata: dict[str, str] = {}
        self._truncated = False
        self._ended: str | None = None
        self._finished = False
        self._started = False
        self._channels: dict[int, Channel] = {}
        self._pending: list[RawChunk | StreamEvent] = []  # items before the trial metadata (none from a Recorder)
        self._file = open(path, "rb")  # noqa: SIM115 - closed at the end of the iteration or by close()
        self._records = StreamReader(self._file).records
        try:
            self._read_metadata()
        except BaseException:
            self.close()
            raise

    def _read_metadata(self) -> None:
        """Read up to the ``trial`` metadata (the first record a Recorder writes after the header)."""
        try:
            for record in self._records:
                if isinstance(record, Metadata) and record.name == "trial":
                    self.metadata = dict(record.metadata)
                    break
                item = self._take(record)
                if item is not None:
                    self._pending.append(item)
            else:
                self._finish()
        except (McapError, EOFError, struct.error, ValueError) as exc:
            short = isinstance(exc, (EndOfFile, EOFError, struct.error))
            reason = "the file ends before the trial metadata" if short else str(exc)
            raise ValueError(f"{self.path}: not a turntable-hil recording ({reason})") from None
        if self.metadata.get("format") != FORMAT:
            raise ValueError(f"{self.path}: not a turntable-hil recording (format {self.metadata.get('format')!r})")

    def __iter__(self) -> Iterator[RawChunk | StreamEvent]:
        if self._started:
            raise RuntimeError(f"{self.path}: a recording's items are read once")
        self._started = True
        yield from self._pending
        self._pending = []
        if self._finished:
            return
        try:
            for record in self._records:
                item = self._take(record)
                if item is not None:
                    yield item
        except (McapError, EOFError, struct.error, ValueError):
            self._truncated = True
        except OSError as exc:  # the disk, not the file's content: say so, in one line
            self._finish()
            raise DataError.unreadable(self.path, exc) from None
        self._finish()

    def _take(self, record: object) -> RawChunk | StreamEvent | None:
        """The item of a message record; the other records update the reader's state."""
        if isinstance(record, Message):
            return _item(self._channels[record.channel_id], record)
        if isinstance(record, Channel):
            self._channels[record.id] = record
        elif isinstance(record, Metadata) and record.name == "trial_end":
            self._ended = record.metadata.get("ended")
        return None

    def _finish(self) -> None:
        self._finished = True
        self.close()

    @property
    def truncated(self) -> bool:
        """The file ended inside a record (the process was killed); known after the iteration."""
        self._require_read()
        return self._truncated

    @property
    def ended(self) -> str | None:
        """How the live trial ended (the ``trial_end`` record, written last); known after the iteration."""
        self._require_read()
        return self._ended

    def _require_read(self) -> None:
        if not (self._finished and self._started):
            raise RuntimeError(f"{self.path}: truncated and ended are known once every item has been read")

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> RecordingReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_recording(path: str | Path) -> Recording:
    """Read a recording whole (see :class:`RecordingReader`); raises ValueError if it is not one."""
    with RecordingReader(path) as reader:
        items = list(reader)
    return Recording(reader.metadata, items, reader.truncated, reader.ended)


def _item(channel: Channel, message: Message) -> RawChunk | StreamEvent:
    if channel.topic == EVENTS:
        fields = json.loads(message.data)
        return StreamEvent(fields["stream"], message.log_time / 1e9, StreamEventKind(fields["event"]),
                           fields.get("detail", ""))
    return decode_chunk(channel.topic, channel.message_encoding, message.log_time, message.data)
