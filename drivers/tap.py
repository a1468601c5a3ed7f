"""Listeners on a device reader: the raw tap (every chunk before parsing), as python-can's Listener."""

from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path

import can

from drivers.codec import RawChunk, StreamEvent


class RawListener(ABC):
    """Receives every raw chunk a device session reads, good or bad, before it is parsed."""

    @abstractmethod
    def on_raw(self, chunk: RawChunk) -> None:
        """Called from the session's reader thread; keep it short."""

    def on_event(self, event: StreamEvent) -> None:
        """The transport failed or came back (called from the reader thread)."""

    def stop(self) -> None:
        """The session has ended; flush and release resources."""


class CanLogTap(RawListener):
    """Writes raw CAN chunks to any python-can log file (.blf, .asc, .log, .csv, .trc) by extension."""

    def __init__(self, path: str | Path, channel: str = "hil") -> None:
        self._writer = can.Logger(str(path))
        self._channel = channel

    def on_raw(self, chunk: RawChunk) -> None:
        if chunk.arbitration_id is not None:
            self._writer.on_message_received(chunk_to_message(chunk, self._channel))

    def stop(self) -> None:
        self._writer.stop()


def chunk_to_message(chunk: RawChunk, channel: str | None = None) -> can.Message:
    """The CAN message of a raw CAN chunk."""
    return can.Message(timestamp=chunk.host_time, arbitration_id=chunk.arbitration_id,
                       is_extended_id=chunk.is_extended_id, data=chunk.data, channel=channel)


def message_to_chunk(message: can.Message, stream: str) -> RawChunk:
    """The raw chunk of a received CAN message (its own timestamp is the host time)."""
    return RawChunk(stream, message.timestamp, bytes(message.data), message.arbitration_id,
                    message.is_extended_id)
