"""What the pipeline publishes: one immutable Progress per item, the same to the caller and to every listener,
whose blocks and snapshots add up to everything the estimator took and solved."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tests.helpers import make_config

from emulators.simulation import Simulation
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.samples import AlignedBatch


def _fed(batches: list[AlignedBatch]):
    heard = []
    settings = PipelineSettings.of(make_config(duration=20.0, rate=100.0))
    processor = TrialProcessor(settings, listeners=[heard.append, heard.append])
    returned = [processor.feed_batch(batch) for batch in batches]
    return returned, heard, processor.finished()


def test_every_listener_hears_each_progress_the_caller_gets_in_order():
    batches = list(Simulation.from_config(make_config(duration=20.0, rate=100.0)).batches(chunk=300))
    returned, heard, _ = _fed(batches)
    assert len(returned) == len(batches) > 3
    assert all(a is b is c for a, b, c in zip(returned, heard[0::2], heard[1::2]))
    with pytest.raises(dataclasses.FrozenInstanceError):
        returned[0].trial_time = 0.0  # type: ignore[misc]
    # nor can a listener change what the next one hears through the counts or the health
    with pytest.raises(TypeError):
        returned[0].health["aligner"]["aligned"] = 0  # type: ignore[index]
    with pytest.raises(TypeError):
        returned[0].counts.extra["imu_missing"] = 0  # type: ignore[index]


def test_the_blocks_taken_and_the_snapshots_published_are_all_the_estimator_had():
    batches = list(Simulation.from_config(make_config(duration=20.0, rate=100.0)).batches(chunk=300))
    returned, _, finished = _fed(batches)
    t0 = batches[0].t0
    samples = [run for progress in returned for run in progress.samples()]
    assert np.array_equal(np.concatenate([r.t for r in samples]), np.concatenate([b.t for b in batches]) - t0)
    assert np.array_equal(np.vstack([r.dv for r in samples]), np.vstack([b.dv for b in batches]))
    table_t = np.concatenate([block.table_t for p in returned for block in p.taken])
    assert np.array_equal(table_t, np.concatenate([r.t for r in samples]))  # every sample had its angles
    published = [snap for progress in returned for snap in progress.snapshots]
    assert published == finished.snapshots and returned[-1].latest is finished.snapshots[-1]
    assert returned[-1].counts.aligned == finished.streams.aligned == sum(len(b) for b in batches)
    assert returned[-1].trial_time == pytest.approx(20.0)


def test_a_batch_without_angles_is_taken_with_nan_rows_and_no_table():
    batch = next(Simulation.from_config(make_config(duration=5.0, rate=100.0)).batches(chunk=10**6))
    bare = AlignedBatch(batch.t, batch.dtheta, batch.dv, None, batch.t0)
    (progress,), _, finished = _fed([bare])
    (run,) = progress.samples()
    assert np.isnan(run.angles).all() and run.angles.shape == (len(bare), 3)
    assert len(progress.taken[0].table_t) == 0
    assert finished.streams.table_frames == 0 and finished.streams.imu_frames == len(bare)
