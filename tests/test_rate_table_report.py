"""What a rate-table trial says of the gyros: their rate against the table's, per axis, in stdout, result.json
and report.html (the gyro bias there, the rate table turning the IMU about its z axis at a steady rate)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from tests.helpers import make_config

from emulators.simulation import Simulation
from hil.cli import main
from hil.outputs.result import summary_text
from hil.pipeline.time_offset import TimeOffsetEstimator
from hil.units import DEG_PER_H

ROOT = Path(__file__).resolve().parents[1]
GYRO_BIAS_DPH = [0.5, -0.3, 0.8]  # configs/rate_table_aerosmith.yaml's imu.errors


def test_the_gyros_rate_error_against_the_table_is_their_bias():
    bias = np.array([50.0, -80.0, 30.0])
    sim = Simulation.from_config(make_config(duration=30, rate=200.0, errors={"gyro_bias_dph": bias.tolist()}))
    batch = next(sim.batches(10**9))
    est = TimeOffsetEstimator(sim.truth.earth, sim.truth.geometry, 200.0)
    est.add(batch.t, batch.dtheta, batch.angles)
    assert est.gyro_rate_error() / DEG_PER_H == pytest.approx(bias, abs=0.05)


@pytest.fixture(scope="module")
def rate_trial(tmp_path_factory):
    out = tmp_path_factory.mktemp("rate") / "out"
    code = main([
        "run", str(ROOT / "configs" / "rate_table_aerosmith.yaml"), "--duration", "30", "--speed", "max", "--quiet",
        "--viewer", "none", "--no-figures", "--no-history", "--out", str(out)])  # fmt: skip
    return code, out


def test_a_rate_table_trial_reports_the_gyro_bias_against_the_table(rate_trial):
    code, out = rate_trial
    assert code == 0
    error = json.loads((out / "result.json").read_text())["streams"]["gyro_rate_error_dph"]
    assert error == pytest.approx(GYRO_BIAS_DPH, abs=0.02)
    report = (out / "report.html").read_text()
    for axis, value in zip("xyz", error):
        row = re.search(rf"<code>gyro_rate_error_{axis}</code>.*?<td class='num'>([^<]*)</td><td>°/h</td>", report)
        assert row and float(row.group(1)) == pytest.approx(value, rel=0.01)


def test_a_rate_table_trials_summary_names_the_gyros(rate_trial):
    _, out = rate_trial
    text = summary_text(json.loads((out / "result.json").read_text()), out)
    line = re.search(r"gyro rate minus the table's \(deg/h\): (.*)", text)
    assert line, text
    assert [float(v) for v in line.group(1).split(", ")] == pytest.approx(GYRO_BIAS_DPH, abs=0.02)
