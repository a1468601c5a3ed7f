"""The IMU/table time-offset diagnostic recovers a known lag of the table angles."""

import pytest
from conftest import make_config

from emulators.simulation import Simulation
from hil.pipeline.time_offset import TimeOffsetEstimator
from hil.samples import AlignedSample


# at 2000 Hz 13 ms lies beyond the cross-correlation's 20 samples: Gauss-Newton takes it from there
@pytest.mark.parametrize("lag, rate", [(0.0, 200.0), (0.002, 200.0), (-0.0007, 200.0), (0.013, 200.0), (0.013, 2000.0)])
def test_offset_of_lagging_table_angles(lag, rate):
    sim = Simulation.from_config(make_config(duration=30, rate=rate))
    batch = next(sim.batches(10**9))
    angles = sim.truth.angles(batch.t - lag)  # the table shows the angles of `lag` earlier
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, rate)
    est.add([AlignedSample(t, tuple(a), tuple(b), tuple(c))
             for t, a, b, c in zip(batch.t, batch.dtheta.tolist(), batch.dv.tolist(), angles.tolist())])
    assert est.estimate() == pytest.approx(lag, abs=2e-6)


def test_static_table_gives_no_offset():
    sim = Simulation.from_config(make_config(duration=20, rate=100.0, kind="static"))
    batch = next(sim.batches(10**9))
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 100.0)
    est.add([AlignedSample(t, tuple(a), tuple(b), tuple(c))
             for t, a, b, c in zip(batch.t, batch.dtheta.tolist(), batch.dv.tolist(), batch.angles.tolist())])
    assert est.estimate() is None


def test_gyro_bias_does_not_move_the_offset():
    sim = Simulation.from_config(make_config(duration=30, rate=200.0, errors={"gyro_bias_dph": [50, -80, 30]}))
    batch = next(sim.batches(10**9))
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 200.0)
    est.add([AlignedSample(t, tuple(a), tuple(b), tuple(c))
             for t, a, b, c in zip(batch.t, batch.dtheta.tolist(), batch.dv.tolist(), batch.angles.tolist())])
    assert est.estimate() == pytest.approx(0.0, abs=2e-6)


def test_windows_between_gaps_are_combined():
    sim = Simulation.from_config(make_config(duration=30, rate=200.0))
    batch = next(sim.batches(10**9))
    angles = sim.truth.angles(batch.t - 0.001)
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 200.0)
    samples = [AlignedSample(t, tuple(a), tuple(b), tuple(c))
               for t, a, b, c in zip(batch.t, batch.dtheta.tolist(), batch.dv.tolist(), angles.tolist())]
    for start in range(0, len(samples), 1000):  # 5 s stretches
        est.add(samples[start:start + 990])
        est.restart()
    assert est.estimate() == pytest.approx(0.001, abs=2e-6)
