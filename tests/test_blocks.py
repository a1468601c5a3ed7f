"""The block stage on hand-made runs: whole blocks at --speed max, everything a read completes at the devices'
speed, a gap or the end closing a block early, and the trial's end cutting a read."""

from __future__ import annotations

import math

import numpy as np

from hil.pipeline.blocks import Blocks, until
from hil.samples import NO_ANGLES, AlignedBatch, ImuGap


def run(start: int, n: int) -> AlignedBatch:
    """Samples ``start + 1 .. start + n`` at 100 Hz, each sample's increments its index."""
    t = (np.arange(start, start + n) + 1) / 100.0
    column = np.arange(start, start + n, dtype=float)[:, None] * np.ones(3)
    return AlignedBatch(t, column, column, np.zeros((n, 3)))


def sizes(out: list) -> list:
    return [len(item) if isinstance(item, AlignedBatch) else "gap" for item in out]


def test_at_speed_max_blocks_are_whole_whatever_the_reads():
    blocks = Blocks(5, math.inf)
    assert sizes(blocks.add([run(0, 7)])) == [5] and blocks.waiting == 2
    out = blocks.add([run(7, 7)])
    assert sizes(out) == [5] and blocks.waiting == 4
    assert out[0].dtheta[:, 0].tolist() == [5, 6, 7, 8, 9]  # the held samples first, in order
    assert sizes(blocks.add([], final=True)) == [4] and blocks.waiting == 0


def test_at_the_devices_speed_a_read_completing_enough_is_taken_whole():
    blocks = Blocks(10, 3)  # take_at: half of what a live read holds
    assert sizes(blocks.add([run(0, 2)])) == [] and blocks.waiting == 2  # 2 < 3: it waits
    assert sizes(blocks.add([run(2, 3)])) == [5] and blocks.waiting == 0  # 3 more: all 5 taken at once


def test_a_gap_closes_the_block_before_it():
    blocks = Blocks(5, math.inf)
    gap = ImuGap(0.03, 0.05, NO_ANGLES, NO_ANGLES)
    assert sizes(blocks.add([run(0, 3), gap, run(5, 6)])) == [3, "gap", 5] and blocks.waiting == 1


def test_the_end_cuts_a_read_and_drops_what_lies_beyond():
    gap = ImuGap(0.10, 0.12, NO_ANGLES, NO_ANGLES)
    kept = until([run(0, 5), run(5, 5), gap], 0.075)
    assert sizes(kept) == [5, 2] and kept[1].t.tolist() == [0.06, 0.07]
    assert sizes(until([run(0, 5), gap, run(12, 3)], 0.13)) == [5, "gap", 1]
