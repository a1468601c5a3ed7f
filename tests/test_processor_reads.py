"""Reads as the processor meets them: a table stream that falls behind the IMU's once both are paired (at the
devices' own speed a table silent for longer than the wait is left behind, and the IMU goes on without it; at
--speed max the table is behind, not silent, and every sample keeps its angles), and one read that carries
samples beyond the trial's duration."""

from __future__ import annotations

import pytest
from tests.helpers import make_config

from drivers.codec import RawChunk
from emulators.simulation import Simulation
from hil.pipeline.decoding import IMU, TABLE
from hil.pipeline.processor import TABLE_WAIT_S, TrialProcessor, table_wait
from hil.pipeline.settings import PipelineSettings
from hil.samples import ImuSample, TableSample

RATE = 100.0
LAG_S = 20.0  # the table's bytes arrive this much trial time after the IMU's ...
LAG_FROM_S = 5.0  # ... from this time on


CFG = make_config(duration=60.0, rate=RATE, errors={"accel_noise_ug": [50, 50, 50], "gyro_noise_dph": [0.01] * 3})
CODECS = PipelineSettings.of(CFG).codecs()
BLOCK = CFG.block_samples  # 5 at 100 Hz: a read aligning 2 or more is taken


def _frames(stream: str, samples) -> bytes:
    codec = CODECS[stream]
    return b"".join(codec.encode(codec.from_sample(s)) for s in samples)


def _trial(duration: float | None, time_scale: float | None) -> tuple[TrialProcessor, list, list]:
    """A processor, and the IMU and table samples of a 60 s swing (sample k ends at k / rate, k = 1 ...)."""
    batch = next(Simulation.from_config(CFG).batches(chunk=10**6))
    imu = [ImuSample(k + 1, tuple(batch.dtheta[k]), tuple(batch.dv[k])) for k in range(len(batch))]
    table = [TableSample(k + 1, tuple(batch.angles[k])) for k in range(len(batch))]
    return TrialProcessor(PipelineSettings.of(CFG), duration, time_scale), imu, table


def _lagging_trial(time_scale: float | None) -> dict:
    """At the devices' speed the table is silent from LAG_FROM_S for LAG_S (its frames of that time are lost);
    at --speed max its frames from LAG_FROM_S on arrive LAG_S late."""
    processor, imu, table = _trial(60.0, time_scale)
    n = len(imu)
    lag, step, lag_from = round(LAG_S * RATE), 50, round(LAG_FROM_S * RATE)  # reads of half a second each
    t = 0.0
    for start in range(0, n + lag, step):
        t += step / RATE / (time_scale or 10.0)
        if start < n:
            processor.feed(RawChunk("imu", t, _frames(IMU, imu[start:start + step])))
        late = start - lag if start >= lag_from + lag else None if start >= lag_from else start
        if time_scale is not None:
            late = start if start < lag_from or start >= lag_from + lag else None
        if late is not None and late < n:
            processor.feed(RawChunk("table", t, _frames(TABLE, table[late:late + step])))
    return processor.finish().streams.extra


def test_the_wait_is_host_seconds_at_the_devices_speed_and_long_at_speed_max():
    assert table_wait(1.0) == TABLE_WAIT_S and table_wait(10.0) == 10 * TABLE_WAIT_S
    assert table_wait(None) > LAG_S


@pytest.mark.parametrize(("time_scale", "without"), [(1.0, True), (None, False)])
def test_imu_samples_go_without_angles_only_when_the_table_is_silent_for_the_wait(time_scale, without):
    extra = _lagging_trial(time_scale)
    assert extra["aligner_aligned"] == round(60.0 * RATE)
    assert (extra["aligner_without_angles"] > 0) is without, extra


def test_a_read_beyond_the_duration_gives_the_estimator_the_trial_and_no_more():
    processor, imu, table = _trial(5.0, 1.0)
    processor.feed(RawChunk("table", 1.0, _frames(TABLE, table[:1000])))  # 10 s in one read each
    progress = processor.feed(RawChunk("imu", 1.0, _frames(IMU, imu[:1000])))
    assert progress.complete and progress.trial_time == pytest.approx(5.0)
    finished = processor.finish()  # what the aligner still held is beyond the end too
    assert finished.estimator.solution().samples == round(5.0 * RATE)
    assert finished.progress.trial_time == pytest.approx(5.0)


def _reads(imu: list, table: list, per_read: int, table_first: list[bool]) -> list[RawChunk]:
    """Both streams' frames in reads of ``per_read`` samples, a read period's table read before its IMU read where
    ``table_first`` says."""
    out = []
    for k, start in enumerate(range(0, len(imu), per_read)):
        at = (start + per_read) / RATE  # the host's clock at the devices' speed
        pair = [RawChunk(IMU, at, _frames(IMU, imu[start:start + per_read])),
                RawChunk(TABLE, at, _frames(TABLE, table[start:start + per_read]))]
        out += pair[::-1] if table_first[k % len(table_first)] else pair
    return out


def test_at_the_devices_speed_each_read_period_is_one_update_taken_by_the_read_that_aligns_it():
    """Reads of a block each (the live default): whichever stream's read comes first, the read that aligns the
    period's samples hands them all to the estimator at once, and none waits for the next read."""
    processor, imu, table = _trial(None, 1.0)
    reads = _reads(imu, table, BLOCK, [False, True, True, False, True])
    updates = 0
    for k in range(0, len(reads), 2):
        processor.feed(reads[k])
        progress = processor.feed(reads[k + 1])
        if updates:  # paired (the reads before waited for the pairing, and were taken at once)
            assert progress.waiting == 0 and progress.updates == updates + 1
        updates = progress.updates
    assert processor.finish().estimator.solution().samples == len(imu)


def test_a_read_that_completes_only_a_few_samples_leaves_them_for_the_next():
    processor, imu, table = _trial(None, 1.0)
    block = BLOCK
    paired = round(2.0 * RATE)  # the first 2 s pair the streams
    for chunk in _reads(imu[:paired], table[:paired], block, [False]):
        progress = processor.feed(chunk)
    updates, at = progress.updates, paired / RATE
    assert updates and progress.waiting == 0
    processor.feed(RawChunk(IMU, at + 0.05, _frames(IMU, imu[paired:paired + block])))
    processor.feed(RawChunk(TABLE, at + 0.05, _frames(TABLE, table[paired:paired + block - 1])))  # 4: taken
    progress = processor.feed(RawChunk(TABLE, at + 0.06, _frames(TABLE, table[paired + block - 1:paired + block])))
    assert (progress.updates, progress.waiting) == (updates + 1, 1)  # 1 more: it waits
    processor.feed(RawChunk(IMU, at + 0.1, _frames(IMU, imu[paired + block:paired + 2 * block])))
    progress = processor.feed(RawChunk(TABLE, at + 0.1, _frames(TABLE, table[paired + block:paired + 2 * block])))
    assert (progress.updates, progress.waiting) == (updates + 2, 0)


def test_at_speed_max_the_result_does_not_depend_on_how_the_bytes_were_read():
    results = []
    for per_read, order in ((10, [False]), (7, [True, False]), (23, [False, True, True])):
        processor, imu, table = _trial(None, None)
        for chunk in _reads(imu, table, per_read, order):
            processor.feed(chunk)
        finished = processor.finish()
        solution = finished.estimator.solution()
        results.append((solution.samples, *solution.full.bias, *solution.full.bias_sigma, finished.progress.updates))
    assert results[0] == results[1] == results[2]
