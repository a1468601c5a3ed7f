"""The IMU/table time-offset diagnostic recovers a known lag of the table angles."""

import numpy as np
import pytest
from tests.helpers import make_config

from emulators.simulation import Simulation
from hil.pipeline.time_offset import TimeOffsetEstimator


# at 2000 Hz 13 ms lies beyond the cross-correlation's 20 samples: Gauss-Newton takes it from there
@pytest.mark.parametrize("lag, rate", [(0.0, 200.0), (0.002, 200.0), (-0.0007, 200.0), (0.013, 200.0), (0.013, 2000.0)])
def test_offset_of_lagging_table_angles(lag, rate):
    sim = Simulation.from_config(make_config(duration=30, rate=rate))
    batch = next(sim.batches(10**9))
    angles = sim.truth.angles(batch.t - lag)  # the table shows the angles of `lag` earlier
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, rate)
    est.add(batch.t, batch.dtheta, angles)
    assert est.estimate() == pytest.approx(lag, abs=2e-6)


def test_static_table_gives_no_offset():
    sim = Simulation.from_config(make_config(duration=20, rate=100.0, kind="static"))
    batch = next(sim.batches(10**9))
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 100.0)
    est.add(batch.t, batch.dtheta, batch.angles)
    assert est.estimate() is None


def test_gyro_bias_does_not_move_the_offset():
    sim = Simulation.from_config(make_config(duration=30, rate=200.0, errors={"gyro_bias_dph": [50, -80, 30]}))
    batch = next(sim.batches(10**9))
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 200.0)
    est.add(batch.t, batch.dtheta, batch.angles)
    assert est.estimate() == pytest.approx(0.0, abs=2e-6)


def test_windows_between_gaps_are_combined():
    sim = Simulation.from_config(make_config(duration=30, rate=200.0))
    batch = next(sim.batches(10**9))
    angles = sim.truth.angles(batch.t - 0.001)
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 200.0)
    for start in range(0, len(batch), 1000):  # 5 s stretches
        est.add(batch.t[start:start + 990], batch.dtheta[start:start + 990], angles[start:start + 990])
        est.restart()
    assert est.estimate() == pytest.approx(0.001, abs=2e-6)


def test_a_sample_without_angles_splits_the_window():
    sim = Simulation.from_config(make_config(duration=30, rate=200.0))
    batch = next(sim.batches(10**9))
    angles = sim.truth.angles(batch.t - 0.001)
    angles[1000::1000] = np.nan  # every 5 s a sample without table angles
    split = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 200.0)
    split.add(batch.t, batch.dtheta, angles)
    assert split.estimate() == pytest.approx(0.001, abs=2e-6)
    assert len(split._done) == 5  # the windows before each of the five samples without angles
