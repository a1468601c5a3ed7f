"""The IMU's frame rate measured on the receive times: an IMU streaming at another rate than ``imu.rate_hz`` ends
the trial early naming both rates and the key, before any check can blame the table; one within 5 % goes on; a
stream losing frames is judged once it loses none; at ``--speed max`` nothing is judged."""

from __future__ import annotations

import pytest
from tests.helpers import make_config

from drivers.codec import RawChunk
from drivers.kvh1750 import Kvh1750Codec
from emulators.simulation import Simulation
from hil.pipeline.decoding import IMU, TABLE, FrameRate
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.samples import ImuSample, TableSample

CFG = make_config(duration=20.0, rate=200.0)
CODECS = PipelineSettings.of(CFG).codecs()


def _fed(device_hz: float, keep=lambda k: True) -> tuple[float, str | None]:
    """A 200 Hz trial's processor fed KVH frames sent at ``device_hz`` (those ``keep`` says arrive) and the
    table's at 200 Hz, in reads of 0.1 s of host time; the host time it stalled at and why (None: it did not)."""
    processor = TrialProcessor(PipelineSettings.of(CFG), 20.0, 1.0)
    imu, table = Kvh1750Codec(device_hz), CODECS[TABLE]  # the IMU's own encoder, at its own rate
    batch = next(Simulation.from_config(make_config(duration=10.0, rate=device_hz)).batches(chunk=10**6))
    step, n = round(device_hz / 10), round(device_hz / 200)
    for read in range(100):
        ks = range(read * step, (read + 1) * step)
        imu_bytes = b"".join(imu.encode(imu.from_sample(ImuSample(k + 1, tuple(batch.dtheta[k]), tuple(batch.dv[k]))))
                             for k in ks if keep(k))
        table_bytes = b"".join(table.encode(table.from_sample(TableSample(k + 1, tuple(batch.angles[n * k + n - 1]))))
                               for k in range(read * 20, (read + 1) * 20))
        host = (read + 1) / 10
        processor.feed(RawChunk("table", host, table_bytes))
        progress = processor.feed(RawChunk("imu", host, imu_bytes))
        if progress.stalled:
            return host, progress.stalled
    return 10.0, None


def test_an_imu_at_1000_hz_configured_at_200_ends_the_trial_naming_both_rates_and_the_key():
    host, why = _fed(1000.0)
    assert host <= 2.5 and why is not None
    assert "1000 frames/s" in why and "imu.rate_hz is 200 Hz" in why and "table" not in why


@pytest.mark.parametrize("device_hz", [192.0, 208.0])
def test_an_imu_within_five_percent_of_its_rate_goes_on(device_hz):
    rate = FrameRate(200.0, 1.0)
    for read in range(31):
        rate.fed(read / 10, round(read / 10 * device_hz), 0)
    assert rate.judged and rate.mismatch is None


def test_a_stream_losing_frames_is_not_judged_on_them():
    assert _fed(200.0, keep=lambda k: k % 10 != 3)[1] is None  # 10 % lost: every read has a gap
    host, why = _fed(1000.0, keep=lambda k: k >= 1500 or k % 10 != 3)  # judged once it loses nothing
    assert host == pytest.approx(3.5) and "1000 frames/s" in why  # 2 s after the read with the last gap


def test_a_stream_without_frames_is_left_to_the_stream_watch():
    rate = FrameRate(200.0, 1.0)
    for read in range(31):
        rate.fed(read / 10, 0, 0)
    assert not rate.judged and rate.mismatch is None
    for read in range(31, 62):  # frames from 3.1 s: judged 2 s later
        rate.fed(read / 10, (read - 30) * 20, 0)
    assert rate.judged and rate.mismatch is None


def test_at_speed_max_the_rate_is_not_judged():
    rate = FrameRate(200.0, None)
    rate.fed(0.0, 0, 0)
    rate.fed(10.0, 100_000, 0)
    assert rate.judged and rate.mismatch is None


def test_a_stall_of_the_host_is_not_taken_for_another_rate():
    rate = FrameRate(200.0, 1.0)
    frames = 0
    for read in range(1, 63):  # reads 20 and 21 find nothing (the host stalled), read 22 the backlog
        frames += {20: 0, 21: 0, 22: 60}.get(read, 20)
        rate.fed(read / 10, frames, 0)
        if read == 21:  # 2 s after the first read: 360 frames, 10 % short, not judged on them
            assert not rate.judged
    assert rate.judged and rate.mismatch is None


def test_a_rate_a_tenth_off_is_named_once_measured_on_six_seconds_of_the_host():
    rate = FrameRate(200.0, 1.0)
    for read in range(1, 100):
        rate.fed(read / 10, read * 22, 0)  # 220 frames/s
        if rate.judged:
            break
    assert read == 61 and "220 frames/s" in rate.mismatch
