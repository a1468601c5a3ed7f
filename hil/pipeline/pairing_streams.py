"""One stream's state in the sync pairing (:mod:`hil.pipeline.sync_pairing`): its offset, the reads it holds,
the receive-time record behind its baseline; and the sample-array operations the pairing needs."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
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
    tried: int | None = None  # newest table pulse (the table's: count) at the last motion search for this stream
    first: int | None = None  # the stream's first counter (unpaced, the coarse offset's; held reads may be trimmed)

    def baseline(self, reads: int = MIN_READS) -> float | None:
        """The least lateness of the paired reads (pulses), once there are ``reads`` of them."""
        return min(v for _, v in self.window) if len(self.window) >= max(reads, 1) else None

    def waited(self, rate: float) -> float:
        """Seconds of the device's time the held samples span."""
        return (int(self.held[-1].sync_index[-1]) - int(self.held[0].sync_index[0])) / rate if self.held else 0.0

    def broken(self, step: int, tolerance: Callable[[], float], cause: str) -> None:
        """The pairing broke where the counter last jumped (by other than ``step``) within the held reads, or
        else at the read whose lateness leapt by more than ``tolerance()`` pulses, or else before them: the samples
        before that are paired as they were (:attr:`before_break`), the rest start the new segment with the reads
        that brought them."""
        held = joined(self.held) if self.held else None
        jumps = np.flatnonzero(np.diff(held.sync_index) != step) if held is not None else []
        late = np.array([e for _, e in self.segment])
        steps = np.abs(np.diff(late))  # a counter that went on by the frames it sent, but not by the time that passed
        ends = np.cumsum([len(read) for read in self.held])  # a read's samples end there in ``held``
        cut = int(jumps[-1]) + 1 if len(jumps) else 0
        if not cut and len(steps) and steps.max() > tolerance():
            cut = int(ends[int(np.argmax(steps))])
        if cut:
            self.before_break = shifted(part(held, np.arange(cut)), self.offset)
            self.segment = [read for read, end in zip(self.segment, ends, strict=True) if end > cut]
            self.held = [part(held, np.arange(cut, len(held)))]
        self.cause = cause
        self.offset_before = self.offset
        self.offset = None
        self.late = 0

    def flushed(self) -> Samples | None:
        """End of data: the held samples of a paired stream, paired as they were (None: unpaired or none held)."""
        if self.offset is None or not self.held:
            return None
        released, self.held = shifted(joined(self.held), self.offset), []
        return released

    def trim(self, span: float) -> int:
        """Drops the oldest held reads beyond ``span`` pulses of the newest sample (one read always stays);
        returns the samples dropped."""
        newest = int(self.held[-1].sync_index[-1])
        dropped = 0
        while len(self.held) > 1 and newest - int(self.held[0].sync_index[-1]) > span:
            dropped += len(self.held.pop(0))
        return dropped

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


def part(samples: Samples, index: np.ndarray) -> Samples:
    """The samples ``index`` (a mask or positions) selects, of either kind."""
    kind = type(samples)
    return kind(*(getattr(samples, name)[index] for name in kind.__dataclass_fields__))
