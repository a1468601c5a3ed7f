"""The sync aligner against the emulator's truth: interpolation, faults, gaps and the estimator bridge."""

import math

import numpy as np
import pytest
from tests.helpers import make_config, scipy_attitude, true_attitude_ib0
from scipy.spatial.transform import Rotation

from emulators.simulation import Simulation
from hil.estimation.online import OnlineEstimator
from hil.pipeline.aligner import Aligner, cumulative_cubic, lagrange_weights
from hil.samples import AlignedSample, ImuGap, ImuSample, TableSample, TableSamples
from hil.units import DEG

RATE = 200.0
DELAY = 50e-6


def test_lagrange_weights_reproduce_a_cubic_on_uneven_knots():
    knots = [0.0, 0.7, 1.1, 2.5]
    cubic = lambda x: 2 - x + 0.5 * x**2 - 0.3 * x**3  # noqa: E731
    for x in (0.2, 1.0, 2.49, 2.5):
        assert np.dot(lagrange_weights(x, knots), [cubic(k) for k in knots]) == pytest.approx(cubic(x), abs=1e-12)


def test_lagrange_weights_of_many_instants_are_those_of_each():
    rng = np.random.default_rng(3)
    knots = np.sort(rng.uniform(0.0, 1.0, (50, 4)), axis=1)
    x = rng.uniform(0.0, 1.0, 50)
    weights = lagrange_weights(x, knots)
    assert weights.shape == (50, 4)
    for k in range(50):
        np.testing.assert_array_equal(weights[k], lagrange_weights(x[k], knots[k]))
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, rtol=1e-12)  # a constant is reproduced


@pytest.mark.parametrize("order", ["one read", "in order", "shuffled"])
def test_table_angles_across_the_wrap_are_unwrapped_by_whole_turns_in_any_order(order):
    """An outer axis turning through 180 deg, reported wrapped to [-180, 180): the aligner's angles are the
    continuous ones, the received angle moved by whole turns, whatever order the samples came in."""
    aligner = Aligner(RATE, RATE)
    k = np.arange(1, 41)
    continuous = np.column_stack((np.radians(150.0 + 2.0 * k), np.zeros(40), np.full(40, 0.1)))
    wrapped = (continuous + math.pi) % (2 * math.pi) - math.pi
    rows = np.random.default_rng(1).permutation(40) if order == "shuffled" else np.arange(40)
    first = np.argsort(rows)[0]  # the knot every turn count goes back to
    samples = [TableSample(int(k[row]), tuple(wrapped[row])) for row in rows]
    if order == "one read":
        aligner.add_tables(TableSamples.stack(samples))
    for sample in samples if order != "one read" else ():
        aligner.add_table(sample)
    knots = aligner._table
    np.testing.assert_array_equal(knots.index, k)
    np.testing.assert_allclose(knots.angles, continuous - continuous[first] + wrapped[first], atol=1e-12)
    turns = (knots.angles - wrapped) / (2 * math.pi)
    np.testing.assert_array_equal(turns, np.round(turns))


def test_cumulative_cubic_recovers_the_increments_hidden_by_a_gap():
    curve = lambda x: np.array([1 + 0.2 * x - 0.01 * x**2 + 0.003 * x**3] * 3)  # noqa: E731
    known = (3.0, 4.0, 5.0)  # cumulative values are only known relative to the first: shift by curve(3)
    y = [curve(x) - curve(3.0) for x in known]
    resume = 9.0
    fit = cumulative_cubic(known, y, resume, [curve(resume) - curve(resume - 1), curve(resume + 1) - curve(resume)])
    for k in range(6, 9):
        np.testing.assert_allclose(fit(k) - fit(k - 1), curve(k) - curve(k - 1), atol=1e-12)


def _streams(duration=20.0, seed=3, drop=0.0, jitter=0.0, swaps=0, duplicates=0):
    """IMU and table samples of the default swing: table latched at pulse + DELAY + jitter, with faults."""
    cfg = make_config(duration=duration, rate=RATE)
    sim = Simulation.from_config(cfg)
    batch = next(sim.batches(chunk=10**9))
    rng = np.random.default_rng(seed)
    n = len(batch)
    k = np.arange(1, n + 1)
    latch = k / RATE + DELAY + rng.normal(0.0, jitter, n)
    angles = sim.truth.angles(latch)
    imu = [ImuSample(int(i), tuple(a), tuple(b)) for i, a, b in zip(k, batch.dtheta.tolist(), batch.dv.tolist())]
    table = [TableSample(int(i), tuple(a), latch_delay=DELAY) for i, a in zip(k, angles.tolist())]
    if drop:
        imu = [s for s in imu if rng.random() >= drop]
        table = [s for s in table if rng.random() >= drop]
    for stream in (imu, table):
        for i in rng.choice(len(stream) - 1, swaps, replace=False):
            stream[i], stream[i + 1] = stream[i + 1], stream[i]
        for i in sorted(rng.choice(len(stream), duplicates, replace=False), reverse=True):
            stream.insert(i, stream[i])
    return sim, batch, imu, table


def flat(released):
    """The aligner's runs as single samples (angles None where a sample has none), gaps as they are."""
    out = []
    for item in released:
        if isinstance(item, ImuGap):
            out.append(item)
            continue
        for t, a, b, g in zip(item.t.tolist(), item.dtheta.tolist(), item.dv.tolist(), item.angles.tolist()):
            out.append(AlignedSample(t, tuple(a), tuple(b), None if math.isnan(g[0]) else tuple(g)))
    return out


def _run(aligner, imu, table):
    """Feed both streams interleaved as they would arrive (table frame k-1 before IMU frame k)."""
    out = []
    j = 0
    for s in imu:
        while j < len(table) and table[j].sync_index < s.sync_index:
            out += aligner.add_table(table[j])
            j += 1
        out += aligner.add_imu(s)
    for s in table[j:]:
        out += aligner.add_table(s)
    return flat(out + aligner.flush())


def _attitude_error_deg(sim, samples):
    t = np.array([s.t for s in samples])
    est = scipy_attitude(sim.truth.geometry, np.array([s.angles for s in samples]))
    ref = scipy_attitude(sim.truth.geometry, sim.truth.angles(t))
    return np.linalg.norm((est.inv() * ref).as_rotvec(), axis=1) / DEG


def test_interpolated_reference_attitude_matches_truth_under_jitter_and_drops():
    sim, _, imu, table = _streams(drop=0.01, jitter=2e-6, swaps=5, duplicates=5)
    aligner = Aligner(RATE, RATE)
    out = _run(aligner, imu, table)
    samples = [s for s in out if isinstance(s, AlignedSample)]
    assert all(s.angles is not None for s in samples)
    error = _attitude_error_deg(sim, samples)
    assert np.sqrt(np.mean(error**2)) < 1e-4
    c = aligner.counters
    assert c.imu_duplicates == 5 and c.table_duplicates == 5
    assert c.imu_filled > 0 and c.imu_bridged == 0 and c.imu_late == 0
    assert [s.t for s in samples] == sorted(s.t for s in samples)
    assert len(samples) == 4000


def test_without_jitter_the_interpolation_error_is_at_rounding_level():
    sim, _, imu, table = _streams(duration=10.0)
    samples = _run(Aligner(RATE, RATE), imu, table)
    assert np.max(_attitude_error_deg(sim, samples)) < 1e-9


def test_short_imu_gap_is_filled_close_to_the_true_increments():
    sim, batch, imu, table = _streams(duration=10.0)
    lost = range(1000, 1004)  # counts 1001..1004
    imu = [s for i, s in enumerate(imu) if i not in lost]
    aligner = Aligner(RATE, RATE)
    samples = _run(aligner, imu, table)
    assert aligner.counters.imu_filled == 4 and aligner.counters.imu_gaps == 1
    filled = np.array([samples[i].dtheta for i in lost])
    np.testing.assert_allclose(filled, batch.dtheta[1000:1004], atol=1e-9)  # 1e-6 of the increment
    filled_dv = np.array([samples[i].dv for i in lost])
    np.testing.assert_allclose(filled_dv, batch.dv[1000:1004], atol=5e-9)  # 1e-7 of the increment


def test_long_imu_gap_is_bridged_by_the_table_attitude():
    sim, batch, imu, table = _streams(duration=30.0)
    imu = [s for s in imu if not 1001 <= s.sync_index <= 1400]  # a 2 s unplug
    aligner = Aligner(RATE, RATE)
    out = _run(aligner, imu, table)
    gaps = [s for s in out if isinstance(s, ImuGap)]
    assert len(gaps) == 1 and aligner.counters.imu_bridged == 400
    assert gaps[0].t_start == pytest.approx(5.0) and gaps[0].t_end == pytest.approx(7.0)

    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=100.0)
    for item in out:
        if isinstance(item, ImuGap):
            assert est.bridge(item)
        else:
            est.update(item)
    true_attitude = true_attitude_ib0(sim.truth, np.array([30.0]))
    error = np.linalg.norm((Rotation.from_matrix(est.strapdown.attitude).inv() * true_attitude).as_rotvec())
    assert error < 1e-9


def test_imu_without_table_goes_out_after_the_wait():
    _, _, imu, _ = _streams(duration=5.0)
    aligner = Aligner(RATE, RATE, table_wait_s=0.5)
    out = []
    for s in imu:
        out += flat(aligner.add_imu(s))
    assert len(out) == len(imu) - 100  # the last 0.5 s waits for a table that never comes
    assert all(s.angles is None for s in out)
    assert len(out + flat(aligner.flush())) == len(imu)


@pytest.mark.parametrize("n", [5, 10])
def test_a_table_latching_every_nth_pulse_is_interpolated_at_every_imu_instant(n):
    """IMU at n x 200 Hz; the table's counter is the pulse count, stepping by n from an odd phase, with a
    frame lost. Its angles at the IMU instants match the analytic swing."""
    imu_rate = n * RATE
    amplitude, period, center = np.radians([8.0, 6.0, 13.0]), np.array([8.0, 10.0, 8.0]), np.radians([5, 2, 6])
    swing = lambda t: amplitude * np.sin(2 * np.pi * np.asarray(t)[:, None] / period) + center  # noqa: E731
    counters = [c for c in range(3, int(10 * imu_rate), n) if c != 3 + 100 * n]
    table = [TableSample(c, tuple(a), latch_delay=DELAY) for c, a in
             zip(counters, swing(np.array(counters) / imu_rate + DELAY).tolist())]
    imu = [ImuSample(k, (0.0,) * 3, (0.0, 0.0, 0.05 / n)) for k in range(20, int(9 * imu_rate))]
    samples = _run(Aligner(imu_rate, imu_rate, 20e-6), imu, table)
    t = np.array([s.t for s in samples])
    np.testing.assert_allclose(t, np.arange(20, int(9 * imu_rate)) / imu_rate + 20e-6, rtol=0, atol=1e-12)
    assert np.max(np.abs(np.array([s.angles for s in samples]) - swing(t))) < 1e-9


@pytest.mark.parametrize("imu_rate, step, duration", [(RATE, 1, 60.0), (2 * RATE, 1, 60.0), (2 * RATE, 2, 60.0)])
def test_free_running_devices_are_aligned_through_their_clock_models(imu_rate, step, duration):
    """No common sync: the IMU counts on a +30 ppm clock, the table latches at 200 Hz on its own -20 ppm clock
    from another origin, counting in steps of ``step``; host receive times are late by 0.3 ms plus
    exponential jitter (mean 0.5 ms)."""
    sim = Simulation.from_config(make_config(duration=duration, rate=RATE))
    rng = np.random.default_rng(4)
    n, m = int(duration * imu_rate), int(duration * RATE)
    k = np.arange(1, n + 1)
    t_imu = k / imu_rate * (1 + 30e-6)  # true end of each IMU interval
    j = np.arange(m)
    t_table = 0.0123 + j / RATE * (1 - 20e-6) + DELAY  # true latch instants
    imu_host = 100.0 + t_imu + 3e-4 + rng.exponential(5e-4, n)
    table_host = 100.0 + t_table + 3e-4 + rng.exponential(5e-4, m)
    dtheta = np.zeros((n, 3))
    imu = [ImuSample(int(a), tuple(d), (0.0, 0.0, 0.05), host_time=float(h)) for a, d, h in zip(k, dtheta, imu_host)]
    table = [TableSample(5000 + step * int(a), tuple(x), host_time=float(h), latch_delay=DELAY)
             for a, x, h in zip(j, sim.truth.angles(t_table).tolist(), table_host)]
    events = sorted([(s.host_time, 0, s) for s in imu] + [(s.host_time, 1, s) for s in table], key=lambda e: e[:2])
    aligner = Aligner(imu_rate, RATE * step, free_running=True)
    out = []
    for _, kind, s in events:
        out += aligner.add_table(s) if kind else aligner.add_imu(s)
    out = flat(out + aligner.flush())
    samples = [s for s in out if isinstance(s, AlignedSample) and s.angles is not None]
    later = [s for s in samples if s.t > 30.0]  # after the fits have settled
    truth_t = np.array([s.t for s in later]) * (1 + 30e-6)  # the IMU's own time line is its count
    est = scipy_attitude(sim.truth.geometry, np.array([s.angles for s in later]))
    ref = scipy_attitude(sim.truth.geometry, sim.truth.angles(truth_t))
    error = np.linalg.norm((est.inv() * ref).as_rotvec(), axis=1) / DEG
    assert np.sqrt(np.mean(error**2)) < 1e-3  # 4.5e-4 deg measured: ~0.03 ms of timing at the swing rates
