"""The trial recording: every raw byte chunk and CAN frame as received, in an MCAP file.

Format (MCAP, https://mcap.dev; readable by any MCAP tool):

- metadata record ``trial`` at the start: ``config`` (the trial YAML as given), ``version`` (this
  package's version), ``format`` (``turntable-hil/1``), ``duration_s`` (the trial length the live
  run used, empty when open-ended), ``time_scale`` (the emulator's speed, 1 for real devices, empty for as fast as possible);
- one channel per stream (``imu``, ``table``, ...), schemaless; its ``message_encoding`` says what a
  message holds: ``application/octet-stream`` (bytes exactly as read from a serial port) or
  ``turntable-hil/can-frame`` (4-byte big-endian arbitration id, 1 flag byte with bit 0 = extended
  id, then the payload);
- metadata record ``trial_end`` at the end, ``ended``: how the live trial ended (``completed``,
  ``early: <reason>``, ``interrupted: <signal>``); absent in a file cut short;
- channel ``events``, JSON messages ``{"stream": .., "event": "outage" | "reconnected", "detail": ..}``;
- ``log_time`` is the host receive time in integer nanoseconds (the pipeline works on that rounded
  time, so a replay sees exactly what the live run saw); ``sequence`` is the global arrival order.

Messages are written unchunked and the file is flushed every ``flush_s`` (0.1 s), so a killed
process loses at most that much; a file cut short is read to its last whole record by
:func:`read_recording`, which uses the non-seeking reader.
"""

from __future__ import annotations

import json
import queue
import struct
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from mcap.exceptions import EndOfFile, McapError
from mcap.records import Channel, Message, Metadata
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer

from drivers.codec import RawChunk, StreamEvent

FORMAT = "turntable-hil/1"
BYTES = "application/octet-stream"
CAN_FRAME = "turntable-hil/can-frame"
EVENTS = "events"
_CAN_HEADER = struct.Struct(">IB")


def package_version() -> str:
    try:
        return version("turntable-hil")
    except PackageNotFoundError:
        return "unknown"


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
                 duration: float | None = None, time_scale: float | None = 1.0) -> None:
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

    def close(self, ended: str | None = None) -> None:
        """Write what is queued, then ``ended`` (how the trial ended) and the MCAP summary."""
        self._queue.put(None)
        self._closing.set()
        self._thread.join()
        if ended is not None:
            self._writer.add_metadata("trial_end", {"ended": ended})
        self._writer.finish()
        self._file.close()

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
    """What a recording holds: the trial metadata and the items in arrival order."""

    metadata: dict[str, str]
    items: list[RawChunk | StreamEvent]
    truncated: bool  # the file ended inside a record (the process was killed)
    ended: str | None = None  # how the live trial ended, when the recorder was closed


def read_recording(path: str | Path) -> Recording:
    """Read a recording front to back, tolerating a file cut short; raises ValueError if it is not one."""
    metadata: dict[str, str] = {}
    channels: dict[int, Channel] = {}
    items: list[RawChunk | StreamEvent] = []
    truncated = False
    ended = None
    with open(path, "rb") as fh:
        try:
            for record in StreamReader(fh).records:
                if isinstance(record, Metadata) and record.name == "trial":
                    metadata = dict(record.metadata)
                elif isinstance(record, Metadata) and record.name == "trial_end":
                    ended = record.metadata.get("ended")
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    items.append(_item(channels[record.channel_id], record))
        except (McapError, EOFError, struct.error, ValueError) as exc:
            if not metadata:
                short = isinstance(exc, (EndOfFile, EOFError, struct.error))
                reason = "the file ends before the trial metadata" if short else str(exc)
                raise ValueError(f"{path}: not a turntable-hil recording ({reason})") from None
            truncated = True
    if metadata.get("format") != FORMAT:
        raise ValueError(f"{path}: not a turntable-hil recording (format {metadata.get('format')!r})")
    return Recording(metadata, items, truncated, ended)


def _item(channel: Channel, message: Message) -> RawChunk | StreamEvent:
    if channel.topic == EVENTS:
        fields = json.loads(message.data)
        return StreamEvent(fields["stream"], message.log_time / 1e9, fields["event"], fields.get("detail", ""))
    return decode_chunk(channel.topic, channel.message_encoding, message.log_time, message.data)
