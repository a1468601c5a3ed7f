"""The frequency response's pairing: a gyro whose output lags the table is paired by its counter and receive
times alone, so that its lag stays in its data, where the response measures it (the swing of
tests/test_sync_pairing.py, its gyro ``LAG`` pulses late)."""

from __future__ import annotations

import numpy as np
from test_sync_pairing import OFFSET, PER, RATE, _inner, _rotations, _table

from hil.pipeline.sync_pairing import RECEIVE_S, SyncPairing
from hil.samples import ImuSamples, TableSamples
from hil.trial.ratetest_live import paired_anew

LAG = 3  # pulses the gyro's output lags its counter


def _lagging_imu(p: np.ndarray, restart: int) -> ImuSamples:
    """IMU samples of pulses p (counters ``p - OFFSET``, from 0 again at pulse ``restart``) whose increments are
    the table's of ``LAG`` pulses before."""
    dtheta = np.zeros((len(p), 3))
    dtheta[:, 1] = _inner(p - LAG) - _inner(p - LAG - 1)
    counters = np.where(p >= restart, p - restart, p - OFFSET)
    return ImuSamples(counters, dtheta, np.zeros((len(p), 3)), np.zeros(len(p)), np.zeros(len(p), dtype=np.int64))


def _received(samples: ImuSamples | TableSamples, h: float) -> ImuSamples | TableSamples:
    fields = type(samples).__dataclass_fields__
    return type(samples)(*(np.full(len(samples.sync_index), h) if f == "host_time" else getattr(samples, f)
                           for f in fields))


def _paired(by_motion: bool, seconds: float = 8.0, restart: int = 1 << 40) -> tuple[SyncPairing, np.ndarray]:
    """Both streams read ``PER`` frames at a time, 1 ms late plus up to 2 ms (seeded), attached at pulse 150 000,
    the IMU power-cycled at pulse ``restart``; the pairing and the IMU pulses it put out."""
    pairing = SyncPairing(RATE, 1, 128, 1.0, (0.0, 0.0), _rotations, by_motion=by_motion)
    rng = np.random.default_rng(7)
    out = []
    for first in range(150_000, 150_000 + int(seconds * RATE), PER):
        p = np.arange(first, first + PER)
        pairing.add_table(_received(_table(p), p[-1] / RATE + 1e-3 + 2e-3 * rng.random()))
        imu = pairing.add_imu(_received(_lagging_imu(p, restart), p[-1] / RATE + 1e-3 + 2e-3 * rng.random()))[1]
        out += [imu.sync_index] if imu is not None else []
    return pairing, np.concatenate(out)


def test_a_lagging_gyro_paired_by_motion_takes_its_lag_for_the_offset():
    report = _paired(by_motion=True)[0].report
    assert report.paired_by == "motion" and report.offset_pulses == OFFSET - LAG  # its data put LAG earlier


def test_a_lagging_gyro_paired_by_its_receive_times_alone_keeps_its_lag_in_its_data():
    pairing, pulses = _paired(by_motion=False)
    report = pairing.report
    assert report.paired_by == "receive_time" and report.offset_pulses == OFFSET and report.repairs == []
    assert np.all(np.diff(pulses) == 1) and pulses[-1] == 150_000 + int(8.0 * RATE) - 1  # none lost
    assert report.unpaired == 0 and pulses[0] == 150_000  # held RECEIVE_S, then all of them paired
    assert RECEIVE_S * RATE <= len(pulses)
    assert paired_anew(report.as_dict()) is None


def test_a_frequency_response_whose_imu_was_paired_anew_says_when_and_why_its_delay_is_not_measured():
    pairing, pulses = _paired(by_motion=False, seconds=16.0, restart=152_000)  # at 10 s, after its first pairing
    report = pairing.report.as_dict()
    assert report["offset_pulses"] == 152_000 and len(report["repairs"]) == 1
    at = report["repairs"][0]["at_s"]
    assert 10.0 + RECEIVE_S <= at <= 10.0 + RECEIVE_S + 0.1  # paired anew once RECEIVE_S of its new counts are held
    assert paired_anew(report).startswith(f"the streams were paired anew at {at:g} s (imu: frames arrived later ")
