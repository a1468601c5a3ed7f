"""Decode a raw capture (a byte dump, or a python-can log for CAN) into a CSV of device-unit fields.

``hil decode PROTOCOL FILE [--out CSV] [--dbc DBC]`` is :func:`main_decode`.
"""

from __future__ import annotations

import argparse
import csv
import inspect
import json
import math
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, TextIO

import can

from drivers.can_dbc import CanDbcCodec
from drivers.codec import RawChunk
from drivers.registry import codec_class
from drivers.tap import message_to_chunk
from hil.config import CanConfig

CAN_LOG_SUFFIXES = (".blf", ".asc", ".log", ".csv", ".trc", ".mf4")
DEFAULT_DBC = CanConfig().dbc  # the shipped DBC the config defaults to
CHUNK = 1 << 16


def decode_capture(protocol: str, path: str | Path, out_csv: str | Path | TextIO | None = None,
                   dbc: str | Path | None = None, rate_hz: float = 200.0,
                   **codec_options: Any) -> dict[str, int]:
    """Counters {"frames", "corrupt", "skipped_bytes", "gaps"} of a capture; its valid frames go to ``out_csv``.

    One CSV row per valid frame: ``sync_index`` then the frame's fields in device units (unit in each
    column name). ``rate_hz`` only matters for unwrapping counters; ``codec_options`` are the codec's
    own settings (e.g. ``gyro_unit="deg"`` for a KVH 1750 configured so).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"capture {path} does not exist")
    if protocol == "can-dbc":
        codec = CanDbcCodec.for_dbc(dbc or DEFAULT_DBC, rate_hz, **codec_options)
        chunks = _can_log_chunks(path)
    else:
        cls = codec_class(protocol)
        if getattr(cls, "kind", None) not in ("imu", "table"):
            raise ValueError(f"protocol {protocol!r} has no data frames to decode")
        takes_rate = "rate_hz" in inspect.signature(cls).parameters
        codec = cls(rate_hz=rate_hz, **codec_options) if takes_rate else cls(**codec_options)
        chunks = _byte_chunks(path)
    framer = codec.framer()
    with _open_out(out_csv) as out:
        writer = csv.writer(out) if out is not None else None
        if writer:
            writer.writerow(["sync_index", *codec.csv_header()])
        for chunk in chunks:
            for decoded in framer.feed_chunk(chunk):
                if writer:
                    writer.writerow([decoded.sync_index, *codec.csv_row(decoded.record)])
    return framer.counters.as_dict()


def main_decode(argv: Sequence[str] | None = None) -> int:
    """``hil decode``: CSV to --out (or stdout), then the counters as one JSON object on the last line."""
    parser = argparse.ArgumentParser(prog="hil decode", description="Decode a raw capture into a CSV.")
    parser.add_argument("protocol", help="kvh1750, xsens-mtdata2, tts1 or can-dbc")
    parser.add_argument("file", help="raw byte dump, or a python-can log (.blf, .asc, ...) for can-dbc")
    parser.add_argument("--out", help="CSV to write (default: stdout, before the counters)")
    parser.add_argument("--dbc", help=f"DBC for can-dbc (default {DEFAULT_DBC})")
    args = parser.parse_args(argv)
    counters = decode_capture(args.protocol, args.file, args.out or sys.stdout, args.dbc)
    print(json.dumps(counters), flush=True)
    return 0


def _byte_chunks(path: Path) -> Iterator[RawChunk]:
    with path.open("rb") as f:
        while data := f.read(CHUNK):
            yield RawChunk("capture", math.nan, data)


def _can_log_chunks(path: Path) -> Iterator[RawChunk]:
    if path.suffix.lower() not in CAN_LOG_SUFFIXES:
        raise ValueError(f"{path}: a can-dbc capture must be a python-can log ({', '.join(CAN_LOG_SUFFIXES)})")
    for message in can.LogReader(str(path)):
        if not (message.is_error_frame or message.is_remote_frame):
            yield message_to_chunk(message, "capture")


class _open_out:
    """A CSV destination: a path (opened and closed here), an open text stream, or nothing."""

    def __init__(self, target: str | Path | TextIO | None) -> None:
        self.target = target
        self.owned: TextIO | None = None

    def __enter__(self) -> TextIO | None:
        if isinstance(self.target, (str, Path)):
            self.owned = open(self.target, "w", newline="", encoding="utf-8")
            return self.owned
        return self.target

    def __exit__(self, *exc: object) -> None:
        if self.owned is not None:
            self.owned.close()
