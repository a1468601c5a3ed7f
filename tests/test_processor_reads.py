"""Reads as the processor meets them: a table stream that lags the IMU's (at the devices' own speed the IMU
goes on without it after the wait; at --speed max the table is behind, not silent, and every sample keeps its
angles), and one read that carries samples beyond the trial's duration."""

from __future__ import annotations

import pytest
from conftest import make_config

from drivers.codec import RawChunk
from emulators.simulation import Simulation
from hil.pipeline.processor import IMU, TABLE, TABLE_WAIT_S, TrialProcessor, table_wait
from hil.samples import ImuSample, TableSample

RATE = 100.0
LAG_S = 20.0  # the table's bytes arrive this much trial time after the IMU's


def _frames(processor: TrialProcessor, stream: str, samples) -> bytes:
    codec = processor.decoders[stream].codec
    return b"".join(codec.encode(codec.from_sample(s)) for s in samples)


def _trial(duration: float | None, time_scale: float | None) -> tuple[TrialProcessor, list, list]:
    """A processor, and the IMU and table samples of a 60 s swing (sample k ends at k / rate, k = 1 ...)."""
    cfg = make_config(duration=60.0, rate=RATE, errors={"accel_noise_ug": [50, 50, 50], "gyro_noise_dph": [0.01] * 3})
    batch = next(Simulation.from_config(cfg).batches(chunk=10**6))
    imu = [ImuSample(k + 1, tuple(batch.dtheta[k]), tuple(batch.dv[k])) for k in range(len(batch))]
    table = [TableSample(k + 1, tuple(batch.angles[k])) for k in range(len(batch))]
    return TrialProcessor(cfg, duration, time_scale), imu, table


def _lagging_trial(time_scale: float | None) -> dict:
    processor, imu, table = _trial(60.0, time_scale)
    n = len(imu)
    lag, step = round(LAG_S * RATE), 50  # reads of half a second each
    t = 0.0
    for start in range(0, n + lag, step):
        t += step / RATE / (time_scale or 10.0)
        if start < n:
            processor.feed(RawChunk("imu", t, _frames(processor, IMU, imu[start:start + step])))
        if start >= lag:
            processor.feed(RawChunk("table", t, _frames(processor, TABLE, table[start - lag:start - lag + step])))
    processor.finish()
    return processor.streams().extra


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
    processor.feed(RawChunk("table", 1.0, _frames(processor, TABLE, table[:1000])))  # 10 s in one read each
    processor.feed(RawChunk("imu", 1.0, _frames(processor, IMU, imu[:1000])))
    assert processor.complete and processor.trial_time == pytest.approx(5.0)
    processor.finish()  # what the aligner still held is beyond the end too
    assert processor.estimator.solution().samples == round(5.0 * RATE) and processor.trial_time == pytest.approx(5.0)
