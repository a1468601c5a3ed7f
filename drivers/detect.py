"""Which protocol a stretch of raw bytes carries: the search of every registered byte-stream codec's framer
(:func:`drivers.framing.find_frames`) is tried on it, and the one with the most valid frames is named.

Frames count only in runs of :data:`MIN_RUN` or more, each starting where the one before it ended: a
frame found alone in garbage (a false sync word whose checksum happens to match) names nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.framing import ByteCodec, find_frames
from drivers.registry import CODECS

DETECT_BYTES = 1 << 16  # bytes the detector looks at: a few hundred frames of any shipped protocol
MIN_RUN = 3  # consecutive valid frames a protocol needs for them to count
NOMINAL_RATE_HZ = 200.0  # for codecs that take a rate: framing does not depend on it


@dataclass(frozen=True, slots=True)
class Detection:
    """The protocol the bytes decode as, its codec's kind (``imu`` or ``table``) and the frames counted."""

    protocol: str
    kind: str
    frames: int


def byte_codecs() -> dict[str, ByteCodec]:
    """An instance of every registered byte-stream codec (one that cannot be built with its defaults is left out)."""
    codecs = {}
    for name in CODECS.names():
        try:
            cls = CODECS.get(name)
            if issubclass(cls, ByteCodec):
                codecs[name] = cls(NOMINAL_RATE_HZ)
        except Exception:  # a plug-in that needs options, or cannot be loaded: not detected
            continue
    return codecs


def frames_in_runs(codec: ByteCodec, data: bytes) -> int:
    """Valid frames of ``codec`` in ``data`` that belong to runs of at least :data:`MIN_RUN` back-to-back frames."""
    found = find_frames(codec, np.frombuffer(data, np.uint8))
    breaks = np.flatnonzero(found.starts[1:] != (found.starts + found.lengths)[:-1]) + 1
    runs = np.diff(np.concatenate(([0], breaks, [len(found.starts)])))
    return int(runs[runs >= MIN_RUN].sum())


def detect(data: bytes) -> Detection | None:
    """The protocol with the most frames in runs in ``data`` (a few kB up to :data:`DETECT_BYTES`), or None."""
    best: Detection | None = None
    for name, codec in byte_codecs().items():
        frames = frames_in_runs(codec, data)
        if frames and (best is None or frames > best.frames):
            best = Detection(name, codec.kind, frames)
    return best
