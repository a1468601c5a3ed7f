"""The IMU plausibility check: gravity-sized specific force and table-sized rates pass, wild values do not."""

import math

import numpy as np

from hil.pipeline.plausibility import ImuPlausibility, UnitKeys
from hil.samples import ImuSample

G = 9.79


def ok(check, *samples):
    """The check on the samples as one read."""
    return check.ok(np.array([s.dtheta for s in samples]), np.array([s.dv for s in samples]))


def test_plausible_and_implausible_samples():
    check = ImuPlausibility(200.0, G, max_rate=math.radians(200))
    at_rest = ImuSample(1, (1e-7, 0.0, 0.0), (0.0, 0.0, G / 200))
    swinging = ImuSample(2, (math.radians(30) / 200, 0.0, 0.0), (0.01, 0.02, G / 200))
    assert ok(check, at_rest, swinging).all()
    exponent_hit = ImuSample(3, (0.0, 0.0, 0.0), (0.0, 0.0, G / 200 * 2**8))
    spinning = ImuSample(4, (math.radians(500) / 200, 0.0, 0.0), (0.0, 0.0, G / 200))
    free_fall = ImuSample(5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert not ok(check, exponent_hit, spinning, free_fall).any()
    assert check.rejected == 3


def test_small_rotation_vectors_match_scipy():
    import numpy as np
    from scipy.spatial.transform import Rotation

    from hil.pipeline.plausibility import small_rotation_vectors

    v = np.random.default_rng(2).normal(size=(20, 3)) * np.array([[1e-9], [1e-4], [0.5]]).repeat(7, axis=0)[:20]
    np.testing.assert_allclose(small_rotation_vectors(Rotation.from_rotvec(v).as_matrix()), v, atol=1e-15)


def test_gyro_table_gate_passes_clean_increments_and_catches_a_damaged_one():
    import numpy as np
    from tests.helpers import make_config

    from emulators.simulation import Simulation
    from hil.pipeline.plausibility import GyroTableGate

    sim = Simulation.from_config(make_config(duration=10, rate=200.0, errors={"gyro_bias_dph": [0.01] * 3,
                                                                              "gyro_noise_dph": [0.01] * 3}))
    batch = next(sim.batches(10**9))
    gate = GyroTableGate(sim.truth.earth, sim.truth.geometry)
    t_start = np.concatenate(([0.0], batch.t[:-1]))
    starts = sim.truth.angles(t_start)
    dtheta = batch.dtheta.copy()
    dtheta[500, 1] += 2e-5  # a damaged mantissa: 0.2 deg/s for one sample
    good = gate.consistent(t_start, batch.t, starts, batch.angles, dtheta)
    assert not good[500] and good.sum() == len(good) - 1 and gate.rejected == 1


def test_a_wrong_accelerometer_unit_is_named_in_the_diagnosis():
    check = ImuPlausibility(200.0, G, max_rate=math.radians(200))
    in_mps2_read_as_g = ImuSample(1, (0.0, 0.0, 0.0), (0.0, 0.0, G * 9.80665 / 200))
    assert not ok(check, in_mps2_read_as_g)[0]
    keys = UnitKeys("imu.kvh1750.accel_unit", "imu.kvh1750.gyro_unit", "imu.kvh1750.gyro_output")
    assert "imu.kvh1750.accel_unit" in check.diagnosis(keys)
    in_g_read_as_mps2 = ImuSample(2, (0.0, 0.0, 0.0), (0.0, 0.0, G / 9.80665 / 200))
    assert not ok(check, in_g_read_as_mps2)[0]
    assert "accelerometer unit is wrong" in check.diagnosis(keys)


def test_the_rejection_watch_stalls_after_five_seconds_of_samples_and_resets_on_a_taken_one():
    from hil.pipeline.plausibility import RejectionWatch

    watch = RejectionWatch(200.0)
    watch.rejected(999)
    assert not watch.stalled
    watch.taken(3)
    watch.rejected(996)
    assert not watch.stalled
    watch.rejected()
    assert watch.stalled and watch.run == 1000
