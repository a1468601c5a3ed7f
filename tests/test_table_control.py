"""Turntable control in a trial: the motion check, and hil run commanding the emulated table over acl."""

import json
import math

import numpy as np
import pytest
import yaml
from tests.helpers import make_config

from hil.cli import main
from hil.trial.table_control import MotionCheck

ROOT_CONFIG = "configs/emulated_swing.yaml"


def _samples(scale=1.0, offset_deg=0.0, duration=30.0, rate=100.0):
    cfg = make_config(duration=duration, rate=rate)
    axes = [getattr(cfg.turntable.motion.axes, g) for g in ("outer", "middle", "inner")]
    t = np.arange(1, int(duration * rate) + 1) / rate
    angles = np.column_stack([scale * a.amplitude_deg * np.sin(2 * math.pi * t / a.period_s) + a.center_deg
                              + offset_deg for a in axes])
    return cfg, (t, np.radians(angles))


def test_the_commanded_swing_passes_and_a_short_one_fails():
    cfg, good = _samples()
    check = MotionCheck(cfg.turntable, 100.0)
    check.add(*good)
    assert check.failure is None and check.checked_at is not None
    cfg, short = _samples(scale=0.5)
    check = MotionCheck(cfg.turntable, 100.0)
    check.add(*short)
    assert "swings over" in check.failure


def test_angles_at_a_faster_imu_rate_still_fill_a_whole_swing_period():
    cfg, good = _samples(rate=500.0)
    check = MotionCheck(cfg.turntable, 100.0)
    check.add(*good)
    assert check.failure is None and check.checked_at is not None


def test_a_static_table_off_its_position_fails():
    cfg = make_config(duration=10, kind="static")
    _, samples = _samples(scale=0.0, offset_deg=1.0)
    check = MotionCheck(cfg.turntable, 100.0)
    check.add(*samples)
    assert "away from its commanded" in check.failure


def _commanded(tmp_path, config=ROOT_CONFIG, **turntable):
    cfg = yaml.safe_load(open(config))
    cfg["turntable"].update(command_port="emulator", **turntable)
    path = tmp_path / "cmd.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_run_arms_the_emulated_acutrol(tmp_path):
    out = tmp_path / "out"
    code = main(["run", str(_commanded(tmp_path)), "--duration", "30", "--speed", "max", "--quiet",
                 "--viewer", "none", "--no-figures", "--out", str(out)])
    assert code == 3  # completed, but 30 s is too short for the default trial's sigma limit of 5 ug
    result = json.loads((out / "result.json").read_text())
    assert result["ended"] == "completed"
    assert result["trial"]["duration_s"] == pytest.approx(30.0) and result["estimate"]["gram_rank"] == 12
    table = json.loads((out / "emulator.json").read_text())
    assert table["table_modes_off"] == 1 and table["table_modes"] == "Off,Off,Off"
    assert "acutrol: :Mode:Off 3;:Mode:Off 2;:Mode:Off 1 -> OK" in (out / "emulator.log").read_text()


@pytest.mark.parametrize(("config", "modes"), [(ROOT_CONFIG, "Off,Off,Off"),
                                              ("configs/rate_table_aerosmith.yaml", "Off")])
def test_an_interlock_trip_ends_the_trial_and_keeps_its_outputs(tmp_path, capsys, config, modes):
    out = tmp_path / "out"
    code = main(["run", str(_commanded(tmp_path, config, interlock_trip_at_s=20.0)), "--duration", "60", "--speed",
                 "max", "--quiet", "--viewer", "none", "--no-figures", "--out", str(out)])
    assert code == 1
    assert "not moving as commanded" in capsys.readouterr().err
    result = json.loads((out / "result.json").read_text())
    assert result["trial"]["duration_s"] > 20.0  # at --speed max the devices run ahead of the check
    table = json.loads((out / "emulator.json").read_text())
    assert table["table_modes"] == modes and table["table_modes_off"] == 1
