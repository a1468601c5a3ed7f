"""Decode a raw capture (a byte dump, or a python-can log for CAN) into a CSV of device-unit fields
(``hil decode``); name the protocol of a byte dump (``hil decode auto``)."""

from __future__ import annotations

import contextlib
import csv
import math
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
from can.io.blf import BLFParseError
from pydantic import ValidationError

from drivers.can_dbc import CanDbcCodec
from drivers.can_settings import CanConfig
from drivers.codec import RawChunk, raised_flags
from drivers.decoder import StreamDecoder
from drivers.detect import DETECT_BYTES, byte_codecs, detect
from drivers.registry import CODECS
from drivers.tap import message_to_chunk
from hil.config_types import describe_validation
from hil.inputs import InputError
from hil.vocabulary import Stream

CAN_LOG_SUFFIXES = (".blf", ".asc", ".log", ".csv", ".trc", ".mf4")
DEFAULT_DBC = CanConfig().dbc  # the shipped DBC the config defaults to
CHUNK = 1 << 16
# what python-can's log readers raise on a file that is not the log its suffix says
_LOG_ERRORS = (struct.error, zlib.error, ValueError, IndexError, BLFParseError, NotImplementedError)


class CaptureError(InputError, ValueError):
    """A capture that cannot be decoded as asked; the message names the file or argument and the reason."""


def decode_capture(protocol: str, path: str | Path, out_csv: str | Path | None = None,
                   dbc: str | Path | None = None, rate_hz: float = 200.0,
                   **codec_options: Any) -> dict[str, int]:
    """Counters {"frames", "corrupt", "skipped_bytes", "gaps"} of a capture, and for an IMU "invalid" (the frames
    its device's health flags mark invalid); its valid frames go to ``out_csv``.

    One CSV row per valid frame: ``sync_index`` then the frame's fields in device units (unit in each
    column name), and for an IMU ``valid`` (1, or 0 where a health flag is raised). ``rate_hz`` only matters for unwrapping counters; ``codec_options`` are the codec's
    own settings (e.g. ``gyro_unit="deg"`` for a KVH 1750 configured so). Raises :class:`CaptureError`
    when the capture, the protocol, the DBC or the CSV cannot be used, or no valid frame is found.
    """
    cls = _codec_class(protocol)
    if dbc and cls.link != "can":
        raise CaptureError(f"--dbc {dbc}: only for a CAN protocol, not {protocol}")
    path = _capture_file(path)
    if cls.link == "can":
        codec = _can_codec(dbc or DEFAULT_DBC, rate_hz, codec_options)
        if path.suffix.lower() not in CAN_LOG_SUFFIXES:
            raise CaptureError(f"{path}: a can-dbc capture must be a python-can log ({', '.join(CAN_LOG_SUFFIXES)})")
        chunks = _can_log_chunks(path)
    else:
        codec = _byte_codec(cls, rate_hz, codec_options)
        chunks = _byte_chunks(path)
    decoder = StreamDecoder(codec)
    imu = codec.kind == Stream.IMU
    invalid = 0
    try:
        with open(out_csv, "w", newline="", encoding="utf-8") if out_csv else contextlib.nullcontext() as out:
            writer = csv.writer(out) if out is not None else None
            if writer:
                writer.writerow(["sync_index", *codec.csv_header(), *(["valid"] if imu else [])])
            for chunk in chunks:
                frames = decoder.frames(chunk)
                valid = ~raised_flags(codec.health_flags, codec.status_words(frames.rows)).any(axis=1)
                invalid += int(np.count_nonzero(~valid))
                if writer:
                    writer.writerows([int(k), *codec.csv_row(codec.record(row)), *([int(v)] if imu else [])]
                                     for k, row, v in zip(frames.sync_index, frames.rows, valid.tolist()))
    except OSError as exc:
        raise CaptureError(f"{exc.filename or path}: {exc.strerror or exc}") from None
    counters = decoder.counters
    if not counters.frames:
        if out_csv:
            Path(out_csv).unlink()  # a header and no row: no output rather than an empty one
        raise CaptureError(f"{path}: no valid {protocol} frame found ({counters.corrupt} corrupt, "
                           f"{counters.skipped_bytes} bytes skipped); is it a {protocol} capture?")
    return counters.as_dict() | ({"invalid": invalid} if imu else {})


def detect_capture(path: str | Path) -> str:
    """The protocol a byte capture's first :data:`~drivers.detect.DETECT_BYTES` decode as (``hil decode auto``);
    raises :class:`CaptureError` when none does. A CAN log is not detected: its DBC cannot be guessed."""
    path = _capture_file(path)
    try:
        with path.open("rb") as f:
            head = f.read(DETECT_BYTES)
    except OSError as exc:
        raise CaptureError(f"{path}: cannot read: {exc.strerror or exc}") from None
    found = detect(head)
    if found is not None:
        return found.protocol
    if path.suffix.lower() in CAN_LOG_SUFFIXES:
        raise CaptureError(f"{path}: auto detects byte-stream protocols only; a CAN log needs can-dbc (and --dbc)")
    raise CaptureError(f"{path}: no run of {', '.join(byte_codecs())} frames in its first {len(head)} bytes; "
                       "name the protocol")


def _capture_file(path: str | Path) -> Path:
    """``path``, a file with something in it."""
    path = Path(path)
    if not path.is_file():
        raise CaptureError(f"{path}: {'a directory, not a capture' if path.is_dir() else 'no such file'}")
    if path.stat().st_size == 0:
        raise CaptureError(f"{path}: empty file, nothing to decode")
    return path


def _codec_class(protocol: str) -> Any:
    """The codec class of a protocol that has data frames."""
    try:
        cls = CODECS.get(protocol)
    except ValueError as exc:
        raise CaptureError(f"protocol: {exc}") from None
    kind = getattr(cls, "kind", None)
    if kind not in tuple(Stream):
        raise CaptureError(f"protocol {protocol!r}: a {kind or 'non-data'} protocol, no data frames to decode")
    return cls


def _byte_codec(cls: Any, rate_hz: float, options: dict[str, Any]) -> Any:
    """The codec of a byte-stream protocol with the device's output settings ``options``."""
    try:
        return cls(rate_hz, **options)
    except ValidationError as exc:
        raise CaptureError(f"{cls.name} options: {describe_validation(exc)} (--option KEY=VALUE)") from None
    except ValueError as exc:
        message = str(exc) if str(exc).startswith(f"{cls.name}:") else f"{cls.name}: {exc}"
        raise CaptureError(f"{message} (--rate, --option KEY=VALUE)") from None


def _can_codec(dbc: str | Path, rate_hz: float, signals: dict[str, Any]) -> CanDbcCodec:
    """The can-dbc codec of a DBC file."""
    try:
        return CanDbcCodec.for_dbc(dbc, rate_hz, **signals)
    except OSError as exc:
        raise CaptureError(f"{dbc}: cannot read: {exc.strerror or exc}") from None
    except cantools.database.Error as exc:
        raise CaptureError(f"{dbc}: not a usable DBC ({exc})") from None
    except ValueError as exc:  # a DBC without the signals
        raise CaptureError(str(exc) if str(exc).startswith(str(dbc)) else f"{dbc}: {exc}") from None


def _byte_chunks(path: Path) -> Iterator[RawChunk]:
    with path.open("rb") as f:
        while data := f.read(CHUNK):
            yield RawChunk("capture", math.nan, data)


def _can_log_chunks(path: Path) -> Iterator[RawChunk]:
    try:
        for message in can.LogReader(str(path)):
            if not (message.is_error_frame or message.is_remote_frame):
                yield message_to_chunk(message, "capture")
    except _LOG_ERRORS as exc:
        raise CaptureError(f"{path}: not a readable {path.suffix} CAN log ({exc})") from None
