"""The simulation's batches computed ahead on a thread are the batches computed in line."""

import threading

import numpy as np
import pytest

from emulators.simulation import Simulation
from tests.conftest import make_config


def _sim(duration: float = 30.0) -> Simulation:
    return Simulation.from_config(make_config(duration=duration, rate=200.0, errors={"accel_bias_ug": [50, 0, 0]}))


def test_batches_ahead_are_the_batches_in_the_same_order():
    sim = _sim()
    inline = list(sim.batches(chunk=1000))
    sim.batches = lambda: Simulation.batches(sim, chunk=1000)  # small batches: many hand-overs
    ahead = list(sim.batches_ahead(depth=2))
    assert len(ahead) == len(inline) == 6
    for a, b in zip(ahead, inline):
        for name in ("t", "dtheta", "dv", "angles"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert a.t0 == b.t0


def test_an_error_in_the_emulator_reaches_the_consumer():
    sim = _sim()

    def failing():
        yield from Simulation.batches(sim, chunk=1000)
        raise RuntimeError("emulator failed")

    sim.batches = failing
    with pytest.raises(RuntimeError, match="emulator failed"):
        list(sim.batches_ahead())


def test_a_consumer_that_stops_early_stops_the_thread():
    sim = _sim(duration=60.0)
    sim.batches = lambda: Simulation.batches(sim, chunk=500)
    before = threading.active_count()
    ahead = sim.batches_ahead(depth=1)
    next(ahead)
    ahead.close()
    assert threading.active_count() == before
