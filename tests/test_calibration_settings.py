"""What a calibration reads from a config (:class:`CalibrationSettings`): the emulated or simulated IMU's errors are
the truth, a real IMU has none; the fraction of a window's samples that may be missing comes from ``output.limits``;
the schedule's checks and its bound take the settings' blocks; each unit of a units config has its own."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from hil.config import load_config
from hil.frames import TableGeometry
from hil.trial.calibration_outcome import EMULATED_MARGIN, checked_schedule, emulated_length
from hil.trial.calibration_settings import CalibrationSettings
from hil.trial.outcome import TrialSetupError

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
SHORT = CONFIGS / "calibration_short.yaml"


def test_the_emulated_or_simulated_imus_errors_are_the_truth_and_a_real_imu_has_none():
    cfg = load_config(SHORT)
    assert CalibrationSettings.of(cfg).truth == cfg.imu.errors
    real = cfg.model_copy(update={"imu": cfg.imu.model_copy(update={"source": "serial"})})
    assert CalibrationSettings.of(real).truth is None
    assert CalibrationSettings.of(real, simulated=True).truth == cfg.imu.errors


def test_a_window_may_lack_the_missing_and_gated_fractions_together_and_anything_where_neither_is_limited():
    cfg = load_config(SHORT)
    limits = cfg.output.limits
    assert CalibrationSettings.of(cfg).lacking_max == pytest.approx(limits.missing_max + limits.gated_max)
    unlimited = limits.model_copy(update={"missing_max": None, "gated_max": None})
    cfg = cfg.model_copy(update={"output": cfg.output.model_copy(update={"limits": unlimited})})
    assert CalibrationSettings.of(cfg).lacking_max == 1.0


def test_the_schedule_is_checked_against_the_settings_table_and_bounded_at_each_temperature():
    settings = CalibrationSettings.of(load_config(SHORT))
    schedule = checked_schedule(settings)
    one = emulated_length(settings, schedule)
    assert one > EMULATED_MARGIN * (settings.calibration.dwell_s * len(schedule.dwells))
    thermal = settings.calibration.model_copy(update={"temperatures_c": [20.0, 40.0]})
    assert emulated_length(dataclasses.replace(settings, calibration=thermal), schedule) \
        == 2 * (one + thermal.soak.timeout_s)
    slow = settings.turntable.limits.model_copy(update={"rate_dps": (1.0, 1.0, 1.0)})
    table = settings.turntable.model_copy(update={"limits": slow})
    with pytest.raises(TrialSetupError, match=r"^here: .*\(turntable.limits\); nothing was sent$"):
        checked_schedule(dataclasses.replace(settings, turntable=table), "here")


def test_each_unit_has_its_own_mounting_and_errors():
    cfg = load_config(CONFIGS / "calibration_units.yaml", units=True)
    units = {name: CalibrationSettings.of(unit) for name, unit in cfg.unit_configs().items()}
    assert len({settings.geometry for settings in units.values()}) == len(units) > 1
    for name, unit in cfg.unit_configs().items():
        assert units[name].geometry == TableGeometry.from_config(unit.turntable)
        assert units[name].truth == unit.imu.errors
