"""A gyro that clips on a rate step and flags its samples so (the Xsens's clipping_gyro_x/y/z): the pipeline never
takes them, the live sequence still goes through the step on the table's angles, and the step is marked
saturated, left out of the fit and named."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import yaml

from emulators.servo_simulation import ServoSimulation
from hil.config import load_config
from hil.pipeline.progress import Taken
from hil.samples import AlignedBatch
from hil.trial.rate_steps import RateSequence
from hil.trial.ratetest_runner import scale_factor_document, scale_factor_steps
from hil.trial.ratetest_settings import RateTestSettings
from hil.units import DEG

ACUTROL = Path(__file__).resolve().parent.parent / "configs" / "ratetest_acutrol.yaml"
RANGE_DPS = 150.0


def _good_runs(batch: AlignedBatch, period: float) -> tuple[AlignedBatch, ...]:
    """The batch's runs of samples whose gyros are within their range: those the pipeline takes."""
    good = np.all(np.abs(batch.dtheta) < (1.0 - 1e-9) * RANGE_DPS * DEG * period, axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], good.astype(int), [0]])))
    return tuple(AlignedBatch(batch.t[a:b], batch.dtheta[a:b], batch.dv[a:b], batch.angles[a:b])
                 for a, b in zip(edges[::2], edges[1::2]))


def test_a_step_whose_gyro_flags_its_clipping_is_gone_through_marked_saturated_and_named(tmp_path):
    doc = yaml.safe_load(ACUTROL.read_text())
    doc["imu"]["errors"]["gyro_range_dps"] = RANGE_DPS  # the scale_factor block does not know it: only the flags tell
    doc["scale_factor"] = {"rates_dps": [30, 90, 180], "dwell_s": 1, "settle_s": 0.2, "axes": ["x"]}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(doc))
    cfg = load_config(tmp_path / "config.yaml")
    sim = ServoSimulation.from_config(cfg)
    client = sim.command_client(cfg.turntable)
    period = 1.0 / cfg.imu_rate_hz
    settings = RateTestSettings.of(cfg)
    sequence = RateSequence(scale_factor_steps(settings, tuple(client.gimbals)), client, period)
    client.apply_limits()
    sequence.start()
    while not sequence.done and sim.samples < 60.0 / period:  # as the live trial's pipeline hands them over
        batch = sim.step((sim.samples + cfg.block_samples) * period)
        runs = _good_runs(batch, period)
        sequence.on_progress(SimpleNamespace(taken=(Taken(runs, batch.t, batch.angles),), samples=lambda: list(runs)))
    client.close()
    assert sequence.done and sequence.failure is None
    doc = scale_factor_document(settings, sequence.windows(), "completed")
    json.dumps(doc, allow_nan=False)  # a window without samples has null figures, not NaN
    x = doc["axes"]["x"]
    left = {s["rate_dps"]: s["left_out"] for s in x["steps"] if s["saturated"]}
    assert sorted(left) == [-180.0, 180.0]
    assert all(why.endswith("samples flagged invalid by the IMU (a gyro clipping at its range) or lost")
               for why in left.values())
    assert abs(x["scale_factor_ppm"] - 300.0) < 3.0 * x["scale_factor_sigma_ppm"]  # from the steps within the range
