"""The sync pairing stage against a swing whose gyro increments are written down analytically: a single-axis
swing of the inner gimbal (the body's y axis with the default mounting), ``theta(t) = A sin(2 pi t / T)``, whose
increments over (t_k-1, t_k] are ``theta(t_k) - theta(t_k-1)`` exactly (rotations about one axis commute).

The devices count from their own starts: the IMU sample of pulse p carries the unwrapped counter
``p - OFFSET`` (a KVH whose 7-bit counter the decoder has unwrapped), the table sample the count p. Reads of
``PER`` frames arrive at host times ``p_newest / rate + latency + jitter`` (seeded). Each sample's status is its
true pulse p, which the pairing never reads: what came out can be checked against it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.frames import Earth, TableGeometry
from hil.pipeline.motion_match import TableRotations, best_offset
from hil.pipeline.sync_pairing import SyncPairing
from hil.samples import ImuSamples, TableSamples

RATE = 200.0
OFFSET = 123_456 - 37  # table count minus IMU counter at the same pulse
AMPLITUDE, PERIOD = math.radians(13.0), 8.0
PER = 4  # frames a read
GEOMETRY, EARTH = TableGeometry(), Earth.from_degrees(32.0)


def _inner(p: np.ndarray, moving: bool = True) -> np.ndarray:
    return AMPLITUDE * np.sin(2 * math.pi * p / RATE / PERIOD) if moving else np.full(len(p), 0.1)


def _imu(p: np.ndarray, moving: bool = True, shift: int = 0) -> ImuSamples:
    """IMU samples of pulses p (their counters ``p - OFFSET - shift``)."""
    dtheta = np.zeros((len(p), 3))
    dtheta[:, 1] = _inner(p, moving) - _inner(p - 1, moving)
    return ImuSamples(p - OFFSET - shift, dtheta, np.zeros((len(p), 3)), np.zeros(len(p)), p.astype(np.int64))


def _table(p: np.ndarray, moving: bool = True, shift: int = 0) -> TableSamples:
    """Table samples of pulses p (their counts ``p - shift``)."""
    angles = np.zeros((len(p), 3))
    angles[:, 2] = _inner(p, moving)
    return TableSamples(p - shift, angles, np.zeros(len(p)), np.zeros(len(p)), p.astype(np.int64))


def _rotations(counts: np.ndarray, angles: np.ndarray) -> TableRotations:
    return TableRotations(GEOMETRY, EARTH, RATE, 1, counts, angles)


def _pairing(time_scale: float | None = 1.0) -> SyncPairing:
    return SyncPairing(RATE, 1, 128, time_scale, (0.0, 0.0), _rotations)


def _run(pairing: SyncPairing, start: int, stop: int, *, moving: bool = True, shift=lambda p: 0, late=lambda p: 0.0,
         jitter: float = 0.5e-3, seed: int = 1, table_at=lambda p: (0, 0.0)) -> dict[str, list]:
    """Reads of both streams for pulses [start, stop); returns what came out, per stream. ``table_at(p)`` gives the
    table's counter shift and extra lateness (s) at pulse p; a shift of None: the table is silent."""
    rng = np.random.default_rng(seed)
    out: dict[str, list] = {"imu": [], "table": []}
    for first in range(start, stop, PER):
        p = np.arange(first, min(first + PER, stop))
        for name in ("table", "imu"):
            table_shift, table_late = table_at(p[-1])
            if name == "table" and table_shift is None:
                continue
            samples = _table(p, moving, table_shift) if name == "table" else _imu(p, moving, shift(p[-1]))
            h = p[-1] / RATE + 1e-3 + late(p[-1]) + (table_late if name == "table" else 0.0) + jitter * rng.random()
            samples = type(samples)(*(np.full(len(p), h) if f == "host_time" else getattr(samples, f)
                                      for f in type(samples).__dataclass_fields__))
            table, imu = pairing.add_table(samples) if name == "table" else pairing.add_imu(samples)
            out["table"] += [table] if table is not None else []
            out["imu"] += [imu] if imu is not None else []
    return out


def _pulses(parts: list) -> np.ndarray:
    return np.concatenate([s.sync_index for s in parts]) if parts else np.zeros(0, dtype=np.int64)


def test_the_motion_decides_the_offset_and_only_there_the_gyros_match_the_table():
    p = np.arange(1000, 1800)
    imu, table = _imu(p), _table(p)
    rotations = _rotations(table.sync_index, table.angles)
    assert rotations.moving
    match = best_offset(imu.sync_index, imu.dtheta, rotations, np.arange(OFFSET - 20, OFFSET + 21))
    assert match.offset == OFFSET
    assert best_offset(imu.sync_index, imu.dtheta, rotations, np.arange(OFFSET + 1, OFFSET + 21)).offset is None  # edge


def test_a_table_at_rest_or_at_a_constant_rate_shows_no_time():
    p = np.arange(0, 400)
    still = _table(p, moving=False)
    assert not _rotations(still.sync_index, still.angles).moving
    turning = _table(p)
    turning.angles[:, 2] = 0.2 * p / RATE  # 0.2 rad/s, constant
    assert not _rotations(turning.sync_index, turning.angles).moving


def test_attached_late_to_a_moving_table_the_imu_is_paired_by_motion_to_the_exact_pulse():
    pairing = _pairing()
    out = _run(pairing, 150_000, 150_000 + 2000)
    report = pairing.report
    assert report.paired_by == "motion" and report.offset_pulses == OFFSET and report.confirmed_at_s < 1.0
    imu = _pulses(out["imu"])
    assert report.unpaired == 0 and imu[0] == 150_000 and np.all(np.diff(imu) == 1)  # every sample, on the table's count
    assert imu[-1] >= 150_000 + 2000 - PER


def test_a_static_table_is_paired_by_receive_time_and_says_how_well():
    pairing = _pairing()
    _run(pairing, 150_000, 150_000 + 600, moving=False)
    report = pairing.report
    assert report.paired_by == "receive_time" and report.confirmed_at_s is None
    assert abs(report.offset_pulses - OFFSET) <= report.accuracy_ms * 1e-3 * RATE + 1
    assert report.accuracy_ms >= 3.0


@pytest.mark.parametrize(("jump", "cause"), [(152_000 - OFFSET, "later"), (3 * 128, "later"), (-5 * 128, "earlier")])
def test_a_counter_that_jumps_is_noticed_dropped_and_paired_again(jump, cause):
    """An IMU power cycle (its counter from zero) and wraps lost or added in a stall: the receive times break
    the pairing, and the motion finds the new offset."""
    pairing = _pairing()
    at = 152_000
    out = _run(pairing, 150_000, 156_000, shift=lambda p: jump if p >= at else 0)
    report = pairing.report
    assert len(report.repairs) == 1 and cause in report.repairs[0]["cause"]
    assert report.repairs[0]["at_s"] == pytest.approx((at - 150_000) / RATE, abs=0.5), report.repairs
    imu = _pulses(out["imu"])
    assert np.all(np.diff(imu) >= 1) and imu[-1] >= 156_000 - PER  # on the table's count throughout
    assert report.offset_pulses == OFFSET + jump and report.unpaired <= 2 * PER


def test_a_power_cycled_table_re_paired_a_pulse_off_by_its_receive_times_gives_no_sample_the_wrong_angles():
    """The table is silent for 1 s, then counts from zero, and its reads now come a pulse later than before:
    its receive times put its new count a pulse off. The table's samples wait until the motion against the
    IMU's places them, so every IMU sample meets the table angles of its own pulse, and the IMU is never moved."""
    pairing = _pairing()
    off, on = 152_000, 152_200  # silent from off, counting from zero at on

    def table_at(p: int) -> tuple[int | None, float]:
        return (0, 0.0) if p < off else (None, 0.0) if p < on else (on, 1.0 / RATE)

    out = _run(pairing, 150_000, 155_000, table_at=table_at)
    report = pairing.report
    assert [r["cause"].split(":")[0] for r in report.repairs] == ["table"], report.repairs  # the IMU never moved
    assert report.paired_by == "motion" and report.offset_pulses == OFFSET - on  # the IMU's, in the table's new count
    table_true = dict(zip(_pulses(out["table"]).tolist(), np.concatenate([t.status for t in out["table"]]).tolist()))
    imu_pulse, imu_true = _pulses(out["imu"]), np.concatenate([s.status for s in out["imu"]])
    met = np.array([table_true.get(k, -1) for k in imu_pulse.tolist()])  # the table's true pulse at each IMU sample
    after = imu_pulse >= on
    assert np.count_nonzero(after) >= 155_000 - on - PER  # the IMU samples after the restart went out ...
    assert np.array_equal(met[met >= 0], imu_true[met >= 0]) and np.all(met[after] >= 0)  # ... each at its own angles


def test_a_host_that_was_only_late_keeps_the_pairing():
    pairing = _pairing()
    out = _run(pairing, 150_000, 153_000, late=lambda p: 0.3 if 151_000 <= p < 151_008 else 0.0)
    assert pairing.report.repairs == [] and pairing.report.unpaired == 0
    assert np.all(np.diff(_pulses(out["imu"])) == 1)


def test_receive_times_that_cannot_tell_the_wraps_apart_end_the_pairing_with_one_line():
    pairing = SyncPairing(2000.0, 10, 128, 1.0, (0.0, 0.0), _rotations)
    rng = np.random.default_rng(3)
    for k in range(40):
        h = k * 0.02 + 0.1 * rng.random()  # reads 50 ms late at the median: more than half the 64 ms counter period
        p = np.arange(k * 40, k * 40 + 40)
        table = _table(p[::10])
        pairing.add_table(TableSamples(table.sync_index, table.angles, np.full(4, h), np.zeros(4), np.zeros(4, int)))
        imu = _imu(p)
        pairing.add_imu(ImuSamples(imu.sync_index, imu.dtheta, imu.dv, np.full(40, h), imu.status))
    assert pairing.failure is not None and "half the IMU counter's period" in pairing.failure
    assert "imu.rate_hz" in pairing.failure and "\n" not in pairing.failure


def test_unpaced_the_first_frames_give_the_coarse_offset_and_the_motion_the_exact_one():
    pairing = _pairing(None)
    _run(pairing, 150_000, 152_000, jitter=0.0, shift=lambda p: 0)
    assert pairing.report.paired_by == "motion" and pairing.report.offset_pulses == OFFSET
    pairing = _pairing(None)
    imu = _imu(np.arange(150_000 + 30, 152_000))  # the IMU's first frames lost: 30 pulses off, found by motion
    pairing.add_table(_table(np.arange(150_000, 152_000)))
    pairing.add_imu(imu)
    assert pairing.report.paired_by == "motion" and pairing.report.offset_pulses == OFFSET


def test_unpaced_a_receive_time_pairing_that_lost_frames_misled_is_set_right_once_the_table_moves():
    """At ``--speed max`` a reader's flush on opening can take a stream's first frames, and the first counters
    then put the coarse offset that many pulses off. On a table at rest that offset stands, by receive time;
    the table's first motion is searched over the whole of the coarse offset's uncertainty and sets it right."""
    start, lost, moves = 150_000, 60, 151_000

    def inner(p: np.ndarray) -> np.ndarray:  # at rest, then the swing from zero
        return np.where(p >= moves, AMPLITUDE * np.sin(2 * math.pi * (p - moves) / RATE / PERIOD), 0.0)

    pairing = _pairing(None)
    for first in range(start, start + 3000, PER):
        p = np.arange(first, first + PER)
        angles = np.zeros((PER, 3))
        angles[:, 2] = inner(p)
        pairing.add_table(TableSamples(p, angles, np.zeros(PER), np.zeros(PER), np.zeros(PER, dtype=np.int64)))
        p = p[p >= start + lost]  # the IMU's first frames were flushed
        dtheta = np.zeros((len(p), 3))
        dtheta[:, 1] = inner(p) - inner(p - 1)
        pairing.add_imu(ImuSamples(p - OFFSET, dtheta, np.zeros((len(p), 3)), np.zeros(len(p)),
                                   np.zeros(len(p), dtype=np.int64)))
        if first == moves - PER:  # still at rest: paired by the first counters, 60 pulses off
            assert pairing.report.paired_by == "receive_time" and pairing.report.offset_pulses == OFFSET - lost
    report = pairing.report
    assert report.paired_by == "motion" and report.offset_pulses == OFFSET
    assert [r["cause"] for r in report.repairs] == [f"imu: gyro/table disagreement ({lost:+d} pulses)"]
    moved_at = (moves - start - lost) / RATE  # trial time counts from the first IMU sample paired
    assert moved_at < report.repairs[0]["at_s"] < moved_at + 2 * 2.0  # within two checks


def test_unpaced_an_imu_that_lost_seconds_of_its_first_frames_is_still_paired_by_motion_to_the_exact_pulse():
    """A loaded host's reader can flush more than a second of a stream's first frames on opening: the first
    counters then put the coarse offset that far off, and the motion search covers it."""
    pairing = _pairing(None)
    pairing.add_table(_table(np.arange(150_000, 153_000)))
    pairing.add_imu(_imu(np.arange(150_000 + 700, 153_000)))  # 3.5 s of its first frames lost
    assert pairing.report.paired_by == "motion" and pairing.report.offset_pulses == OFFSET


def test_unpaced_an_imu_held_longer_than_its_hold_is_paired_from_its_first_counter_not_its_oldest_kept():
    """A slow table reader: 12 s of IMU reads wait for the table's first (both streams began together); the
    oldest are trimmed as unpaired, and the coarse offset still comes from the IMU's first counter."""
    pairing = _pairing(None)
    for first in range(150_000, 152_400, PER):
        pairing.add_imu(_imu(np.arange(first, first + PER)))
    assert pairing.report.paired_by is None and pairing.report.unpaired > 0
    for first in range(150_000, 152_400, PER):  # the table's reader catches up
        pairing.add_table(_table(np.arange(first, first + PER)))
    _run(pairing, 152_400, 154_000, jitter=0.0)
    assert pairing.report.paired_by == "motion" and pairing.report.offset_pulses == OFFSET
