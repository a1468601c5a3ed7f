"""One stream's state in the sync pairing (:mod:`hil.pipeline.sync_pairing`): its offset, the reads it holds,
the receive-time record behind its baseline; and the sample-array operations the pairing needs."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from hil.samples import ImuSamples, TableSamples

MIN_READS = 8  # reads of a stream before its receive times judge anything

Samples = ImuSamples | TableSamples


@dataclass
class StreamPairing:
    """One stream's pairing state."""

    name: str
    wire: float  # pulses from a frame's pulse to its last byte on the line
    offset: int | None = None  # pulse = counter + offset once paired
    held: list[Samples] = field(default_factory=list)  # waiting for a pairing (or for a late read's verdict)
    segment: list[tuple[float, float]] = field(default_factory=list)  # (h, e) of the reads since the break
    window: deque = field(default_factory=deque)  # (h, e - offset) of the paired reads: the baseline's
    late: int = 0  # late reads in a row (their samples are in ``held``)
    cause: str | None = None  # why the pairing broke, until re-paired
    offset_before: int | None = None  # the offset before the break
    before_break: Samples | None = None  # held samples from before the break, paired as they were: yet to go out
    tried: int | None = None  # newest table pulse at the last motion search for this stream

    def baseline(self, reads: int = MIN_READS) -> float | None:
        """The least lateness of the paired reads (pulses), once there are ``reads`` of them."""
        return min(v for _, v in self.window) if len(self.window) >= max(reads, 1) else None

    def waited(self, rate: float) -> float:
        """Seconds of the device's time the held samples span."""
        return (int(self.held[-1].sync_index[-1]) - int(self.held[0].sync_index[0])) / rate if self.held else 0.0

    def spread(self, quantile: float = 0.9) -> float:
        """Pulses the paired reads' lateness scatters by: its ``quantile`` over its least."""
        values = np.array([v for _, v in self.window])
        return float(np.quantile(values, quantile) - values.min()) if len(values) >= MIN_READS else 0.0


def joined(parts: list[Samples]) -> Samples:
    """One read's worth of samples from several, in order."""
    if len(parts) == 1:
        return parts[0]
    kind = type(parts[0])
    return kind(*(np.concatenate([getattr(p, name) for p in parts]) for name in kind.__dataclass_fields__))


def shifted(samples: Samples, offset: int) -> Samples:
    """The samples with ``sync_index`` moved onto the pulse line."""
    kind = type(samples)
    fields = {name: getattr(samples, name) for name in kind.__dataclass_fields__}
    fields["sync_index"] = samples.sync_index + offset
    return kind(**fields)


def kept(history: tuple[np.ndarray, np.ndarray], pulses: np.ndarray, values: np.ndarray, span: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """History plus new samples, the last ``span`` pulses of it (trimmed when twice that is held)."""
    p, v = np.concatenate((history[0], pulses)), np.concatenate((history[1], values))
    if len(p) and p[-1] - p[0] > 2 * span:
        first = int(np.searchsorted(p, p[-1] - span))
        p, v = p[first:], v[first:]
    return p, v


def part(samples: Samples, index: np.ndarray) -> Samples:
    """The samples ``index`` (a mask or positions) selects, of either kind."""
    kind = type(samples)
    return kind(*(getattr(samples, name)[index] for name in kind.__dataclass_fields__))
