"""The block stage: when the estimator takes the samples the aligner has released.

At the devices' speed it takes every sample waiting once a read completes at least half of what a live read
holds (``take_at``), whichever stream's read aligns them; the few left waiting for a table frame still on the
wire join the next read's. The reads, recorded one message each (a CAN stream's grouped by their receive
times), decide the updates: a replay updates as the live run did. Otherwise (``--speed max``, or a silent
table) it takes whole blocks of ``PipelineSettings.block_samples``, bounded by the samples alone, so a run at ``--speed
max`` gives one result however its bytes were read. A gap or the end closes a block early.
"""

from __future__ import annotations

import math

import numpy as np

from hil.pipeline.settings import PipelineSettings
from hil.samples import AlignedBatch, ImuGap

Released = AlignedBatch | ImuGap


class Blocks:
    """Aligned runs in, the blocks the estimator takes out (with the gaps between them, in order)."""

    def __init__(self, block_samples: int, take_at: float) -> None:
        self.size = block_samples
        self.take_at = take_at
        self.waiting = 0  # aligned samples held for the next block
        self._held: list[AlignedBatch] = []

    @classmethod
    def of(cls, settings: PipelineSettings, time_scale: float | None) -> Blocks:
        """The trial's policy: half of what a live read holds (at ``--speed max`` never: blocks)."""
        size = settings.block_samples
        return cls(size, math.inf if time_scale is None else max(1, size // (2 * settings.reads_per_block)))

    def add(self, ready: list[Released], final: bool = False) -> list[Released]:
        """What one read released (``final``: the last), as blocks and gaps for the estimator."""
        out: list[Released] = []
        take_all = final or sum(len(item) for item in ready if isinstance(item, AlignedBatch)) >= self.take_at
        for item in ready:
            if isinstance(item, AlignedBatch):
                self._held.append(item)
                self.waiting += len(item)
                if not take_all:
                    out += self._take(self.waiting // self.size * self.size, self.size)
                continue
            out += self._take(self.waiting, self.waiting)
            out.append(item)
        if take_all:
            out += self._take(self.waiting, self.waiting)
        return out

    def _take(self, n: int, block: int) -> list[AlignedBatch]:
        """The first ``n`` samples held, ``block`` at a time; the rest stay held."""
        if not n:
            return []
        run = joined(self._held)
        taken = [part(run, start, start + block) for start in range(0, n, block)]
        self._held, self.waiting = [part(run, n, len(run))] if n < len(run) else [], len(run) - n
        return [b for b in taken if len(b)]


def until(ready: list[Released], end: float) -> list[Released]:
    """``ready`` up to the trial time ``end`` (a read's samples beyond it stay in the recording only)."""
    kept: list[Released] = []
    for item in ready:
        if isinstance(item, ImuGap):
            if item.t_end > end:
                break
            kept.append(item)
            continue
        n = int(np.searchsorted(item.t, end, side="right"))
        if n:
            kept.append(item if n == len(item) else part(item, 0, n))
        if n < len(item):
            break
    return kept


def part(run: AlignedBatch, start: int, stop: int) -> AlignedBatch:
    """Samples ``start:stop`` of a run."""
    return AlignedBatch(run.t[start:stop], run.dtheta[start:stop], run.dv[start:stop], run.angles[start:stop],
                        valid=None if run.valid is None else run.valid[start:stop])


def joined(runs: list[AlignedBatch]) -> AlignedBatch:
    """One run of consecutive runs (at least one)."""
    if len(runs) == 1:
        return runs[0]
    valid = None if all(r.valid is None for r in runs) else np.concatenate(
        [np.ones(len(r), dtype=bool) if r.valid is None else r.valid for r in runs])
    return AlignedBatch(*(np.concatenate([getattr(r, name) for r in runs]) for name in ("t", "dtheta", "dv", "angles")),
                        valid=valid)
