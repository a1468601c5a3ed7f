"""The simulation process: the child's batches are the batches computed in line, its errors reach the
consumer, a consumer that stops early ends it, and the config it is given is the config."""

import io
from pathlib import Path

import numpy as np
import pytest
import yaml

from emulators.simulation import Simulation
from emulators.simulation_process import HEADER, SimulationProcess, _read_batch, _write_batch
from hil.config import Config, InputError, load_config, parse_config
from hil.samples import AlignedBatch
from tests.helpers import make_config

ROOT = Path(__file__).resolve().parent.parent
TRIAL_CONFIGS = sorted(p.name for p in (ROOT / "configs").glob("*.yaml")
                       if not p.name.startswith(("campaign_", "plan_")))  # campaigns and plans name a config
ERRORS = {"accel_bias_ug": [50, 0, 0], "accel_noise_ug": [20, 20, 20], "gyro_random_walk_dph_per_sqrt_h": [0.01] * 3}


def _assert_same(got: list[AlignedBatch], want: list[AlignedBatch]) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want):
        assert a.t0 == b.t0
        for name in ("t", "dtheta", "dv", "angles"):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None) == (y is None)
            if x is not None:
                assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()


@pytest.mark.parametrize("cfg", [make_config(duration=60.0, rate=200.0, errors=ERRORS),  # three batches
                                 load_config(ROOT / "configs" / "liu2019_sim.yaml")], ids=["short", "liu2019"])
def test_the_childs_batches_are_the_batches_computed_in_line(cfg):
    with SimulationProcess() as simulation:
        got = list(simulation.batches(cfg))
    _assert_same(got, list(Simulation.from_config(cfg).batches()))


def test_a_config_handed_ahead_of_the_reading_gives_the_same_batches():
    cfg = make_config(duration=60.0, rate=200.0, errors=ERRORS)
    with SimulationProcess() as simulation:
        simulation.start(cfg)  # as hil simulate does before it imports the estimator
        got = list(simulation.batches(cfg))
    _assert_same(got, list(Simulation.from_config(cfg).batches()))


def test_a_batch_crosses_the_pipe_as_it_is_with_or_without_angles_and_temperatures():
    rng = np.random.default_rng(4)
    batches = [AlignedBatch(np.arange(1.0, 4.0), rng.normal(size=(3, 3)), rng.normal(size=(3, 3)), angles, t0,
                            temperature_c=temperature)
               for angles, t0, temperature in ((rng.normal(size=(3, 3)), 0.0, None), (None, 0.1, None),
                                               (None, 0.2, np.array([20.5, 21.0, 21.5])))]
    stream = io.BytesIO()
    for batch in batches:
        _write_batch(stream, batch)
    stream.write(HEADER.pack(0, 0.0, False, False))
    stream.seek(0)
    received = list(iter(lambda: _read_batch(stream), None))
    _assert_same(received, batches)
    assert received[1].temperature_c is None
    assert received[2].temperature_c.tolist() == [20.5, 21.0, 21.5]


@pytest.mark.parametrize("name", TRIAL_CONFIGS)
def test_the_config_survives_its_json(name):
    cfg = load_config(ROOT / "configs" / name, units=True)
    assert Config.model_validate_json(cfg.model_dump_json()) == cfg


def test_an_infinite_value_survives_the_json():
    data = yaml.safe_load((ROOT / "configs" / "liu2019_sim.yaml").read_text())
    data.setdefault("output", {}).setdefault("limits", {})["bias_sigma_ug_max"] = float("inf")
    cfg = parse_config(data)
    assert Config.model_validate_json(cfg.model_dump_json()) == cfg


def test_bad_input_in_the_child_is_raised_as_input_error_with_its_message():
    cfg = make_config(duration=None)
    with SimulationProcess() as simulation, pytest.raises(InputError, match=r"^trial\.duration_s: required key"):
        next(simulation.batches(cfg))


def test_any_other_error_in_the_child_is_raised_with_its_last_line():
    class NotAConfig:
        def model_dump_json(self) -> str:
            return '{"trial": {"name": "no site"}}'

    with SimulationProcess() as simulation, pytest.raises(RuntimeError, match="ValidationError: .* site"):
        next(simulation.batches(NotAConfig()))


def test_a_child_killed_midway_is_an_error():
    with SimulationProcess() as simulation:
        batches = simulation.batches(make_config(duration=600.0, rate=200.0))
        next(batches)
        simulation._child.kill()
        with pytest.raises(RuntimeError, match="exit code -9"):
            list(batches)


def _ended(child) -> bool:
    """Reaped (no zombie) and its pipes closed."""
    return child.returncode is not None and child.stdin.closed and child.stdout.closed


def test_a_consumer_that_stops_early_ends_the_child():
    with SimulationProcess() as simulation:
        child = simulation._child
        batches = simulation.batches(make_config(duration=600.0, rate=200.0))  # 24 batches: the child is blocked
        next(batches)
        batches.close()
        assert _ended(child) and child.returncode == -9


def test_an_error_in_the_consumer_ends_the_child():
    with pytest.raises(ZeroDivisionError), SimulationProcess() as simulation:
        child = simulation._child
        for _ in simulation.batches(make_config(duration=600.0, rate=200.0)):
            1 / 0
    assert _ended(child)


def test_a_child_given_no_config_ends_when_closed():
    simulation = SimulationProcess()
    child = simulation._child
    simulation.close()
    assert _ended(child)
