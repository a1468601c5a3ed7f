"""The devices' health flags in the lab form: ``hil emulate`` in its own process, its IMU flagging 1 % of its
samples invalid (a KVH 1750's gyros, as at power-up), and the harness attached late. The trial completes with
the flagged samples counted as the emulator counts them and never estimated (the bias within its sigma of the
truth); the default ``invalid_max`` FAILs it naming the measurement, a looser one passes."""

from __future__ import annotations

import json
import math
import os
import re
import time

import pytest
from lab_form import Emulator, emulated, lab_config, result, within_sigmas

from hil.cli import main
from hil.pytest_plugin import read_cases

RATE_HZ = 200.0
INVALID_RATE = 0.01
pytestmark = [pytest.mark.xdist_group("lab"),
              pytest.mark.skipif(not os.environ.get("HIL_LAB_TESTS"), reason="lab form: set HIL_LAB_TESTS=1")]


def _run(emulator: Emulator, cfg: dict, tmp_path, name: str, **limits: float) -> tuple[int, dict, list]:
    lab = lab_config(cfg, emulator.ports, tmp_path, name=name, limits=limits)
    out = tmp_path / name
    code = main(["run", str(lab), "--duration", "15", "--out", str(out), "--viewer", "none", "--quiet",
                 "--no-figures"])
    failed = [case.name for case in read_cases(out / "junit.xml") if case.outcome == "failed"]
    return code, result(out), failed


def test_one_percent_flagged_completes_counted_never_estimated_and_judged_by_invalid_max(tmp_path):
    cfg = emulated(RATE_HZ, faults={"invalid_rate": INVALID_RATE})
    with Emulator(tmp_path, cfg) as emulator:
        time.sleep(max(0.0, 1.5 - (time.monotonic() - emulator.started)))
        strict = _run(emulator, cfg, tmp_path, "strict")
        loose = _run(emulator, cfg, tmp_path, "loose", invalid_max=0.05)
        emulator.stop()
        stats = json.loads(emulator.stats_file.read_text())["devices"]["imu"]
    sent = stats["faults"]["invalid"] / stats["frames"]  # the emulator's own count, over every frame it wrote
    assert abs(sent - INVALID_RATE) < 4 * math.sqrt(INVALID_RATE / stats["frames"]), stats
    for code, doc, failed in (strict, loose):
        streams = doc["streams"]
        n = streams["aligned"]
        assert doc["ended"] == "completed", doc["ended"]
        assert abs(streams["imu_invalid"] / n - sent) < 4 * math.sqrt(sent / n), streams  # counting error
        assert streams["imu_invalid_by_flag"] == {f"gyro_{a}_invalid": streams["imu_invalid"] for a in "xyz"}
        assert streams["imu_gated"] == 0
        assert within_sigmas(doc, 3.0), doc["estimate"]
    assert (strict[0], strict[2]) == (3, ["imu_invalid_fraction"]), strict[2]
    assert (loose[0], loose[2]) == (0, []), loose[2]


def test_an_imu_streaming_at_another_rate_than_configured_ends_the_trial_naming_imu_rate_hz(tmp_path, capsys):
    """An emulated KVH 1750 at 1000 Hz, the config saying 200 Hz and the configuration query off (a read-only
    line): the trial ends early within seconds naming both rates and the key, not the table."""
    cfg = emulated(1000.0, baudrate=921600)
    with Emulator(tmp_path, cfg) as emulator:
        time.sleep(max(0.0, 1.0 - (time.monotonic() - emulator.started)))
        unchecked = {**cfg["imu"], "rate_hz": RATE_HZ, "options": {"check_config": False}}
        lab = lab_config({**cfg, "imu": unchecked}, emulator.ports, tmp_path)
        started = time.monotonic()
        code = main(["run", str(lab), "--duration", "20", "--out", str(tmp_path / "run"), "--viewer", "none",
                     "--quiet", "--no-figures"])
        took = time.monotonic() - started
    ended = result(tmp_path / "run")["ended"]
    assert code == 1 and took < 8.0, (code, took, ended)
    sends = re.search(r"the IMU sends ([0-9.]+) frames/s", ended)
    assert sends and abs(float(sends[1]) - 1000.0) < 150.0 and "imu.rate_hz is 200 Hz" in ended, ended  # a busy host
    assert "turntable" not in ended, ended
