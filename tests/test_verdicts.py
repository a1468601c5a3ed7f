"""A verdict a lab can sign: a trial that did not complete is never PASS (stdout, report.html, junit.xml,
result.json, the history), a completed trial's estimate holding NaN is not completed, and ``hil report`` exits as
the trial's verdict."""

from __future__ import annotations

import json
import signal
import sqlite3
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from hil.cli import main
from hil.config import ReportLimits
from hil.outputs.result import ENDED_EARLY, INTERRUPTED, trial_verdict
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.samples import AlignedBatch
from hil.trial.outcome import OutputSettings, TrialOutcome
from tests.helpers import make_config

ROOT = Path(__file__).resolve().parents[1]


def _badge(page: str) -> str:
    return page.split('<div class="verdict ', 1)[1].split('"', 1)[0]


def test_interrupted_calibration_is_never_reported_pass(tmp_path):
    out, history = tmp_path / "out", tmp_path / "history.sqlite"
    config = ROOT / "configs" / "calibration_short.yaml"
    proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "calibrate", str(config), "--speed", "4", "--quiet",
                             "--viewer", "none", "--no-figures", "--out", str(out), "--history", str(history)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        recording = out / "recording.mcap"
        while not (recording.exists() and recording.stat().st_size > 50_000):
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 1, stderr
    assert "PASS" not in stdout and "report: INTERRUPTED" in stdout
    result = json.loads((out / "result.json").read_text())
    assert result["ended"] == "interrupted: SIGINT" and result["verdict"] == INTERRUPTED
    assert _badge((out / "report.html").read_text()) == INTERRUPTED
    suite = ET.parse(out / "junit.xml").getroot()
    assert suite.get("errors") == "1"
    with sqlite3.connect(history) as db:
        assert db.execute("SELECT ended, verdict FROM trials").fetchall() == [("interrupted: SIGINT", INTERRUPTED)]


def test_a_trial_that_did_not_complete_has_its_ending_for_verdict():
    assert trial_verdict("completed", "PASS") == "PASS"
    assert trial_verdict("completed", "FAIL") == "FAIL"
    assert trial_verdict("interrupted: SIGTERM", "PASS") == INTERRUPTED
    assert trial_verdict("early: no data from the devices within 15 s", "PASS") == ENDED_EARLY


def _simulated_outcome(tmp_path: Path, scale: float = 1.0) -> TrialOutcome:
    """A short simulated swing whose accelerometer increments are multiplied by ``scale`` past 10 s."""
    from emulators.simulation import Simulation

    cfg = make_config(duration=30.0)
    processor = TrialProcessor(PipelineSettings.of(cfg))
    for batch in Simulation.from_config(cfg).batches():
        dv = np.where((batch.t > 10.0)[:, None], batch.dv * scale, batch.dv)
        processor.feed_batch(AlignedBatch(batch.t, batch.dtheta, dv, batch.angles, batch.t0))
    return TrialOutcome.of(processor.finished(), cfg, "", tmp_path / "out")


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the overflow itself is the data's
def test_an_estimate_holding_nan_is_not_a_completed_trial(tmp_path, capsys):
    outcome = _simulated_outcome(tmp_path, scale=1e305)
    assert outcome.ended.startswith("early: estimate.accel_bias_ug is not finite")
    verdict = outcome.write(figures=False).verdict
    assert verdict == ENDED_EARLY and outcome.exit_code(verdict) == 1
    result = json.loads((outcome.out / "result.json").read_text())
    assert result["verdict"] == ENDED_EARLY and result["ended"] != "completed"
    assert "PASS" not in capsys.readouterr().out
    assert _simulated_outcome(tmp_path).ended == "completed"  # the same trial with sane data


def test_report_exits_as_the_trials_verdict(tmp_path, capsys):
    outcome = _simulated_outcome(tmp_path)
    cfg = make_config(duration=30.0)  # the trial's, with a limit it fails
    failing = cfg.output.model_copy(update={"limits": ReportLimits(bias_sigma_ug_max=1e-9)})
    cfg = cfg.model_copy(update={"output": failing})
    outcome.settings = OutputSettings.of(cfg)
    outcome.config_text = cfg.model_dump_json()  # read back as YAML by hil report
    assert outcome.exit_code(outcome.write(figures=False).verdict) == 3
    assert main(["report", str(outcome.out)]) == 3
    result = json.loads((outcome.out / "result.json").read_text())
    (outcome.out / "result.json").write_text(json.dumps({**result, "ended": "interrupted: SIGINT"}))
    assert main(["report", str(outcome.out)]) == 1
    assert _badge((outcome.out / "report.html").read_text()) == INTERRUPTED


def test_report_rebuilds_a_noise_directory(tmp_path, capsys):
    out = tmp_path / "noise"
    assert main(["noise", str(ROOT / "configs" / "noise_static.yaml"), "--duration", "200", "--out", str(out),
                 "--no-figures", "--no-history"]) == 0
    (out / "report.html").unlink()
    assert main(["report", str(out)]) == 0
    assert "noise" in (out / "report.html").read_text()
    (out / "noise.json").write_text("{\"gyro\": ")  # cut short
    capsys.readouterr()
    assert main(["report", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "noise.json: not a noise.json this version can read (JSONDecodeError" in err
