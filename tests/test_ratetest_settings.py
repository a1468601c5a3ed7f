"""What the rate-table tests read from a config (:class:`RateTestSettings`): the emulated IMU's errors are the
documents' truth, a real IMU has none; a plan step's settings replace the config's block."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from hil.config import load_config
from hil.config_ratetests import FrequencyResponseSettings, ScaleFactorSettings
from hil.trial.ratetest_runner import frequency_response_document, frequency_steps, scale_factor_document
from hil.trial.ratetest_settings import RateTestSettings

ACUTROL = Path(__file__).resolve().parent.parent / "configs" / "ratetest_acutrol.yaml"


def test_the_emulated_imus_errors_are_the_truth_and_a_real_imu_has_none():
    cfg = load_config(ACUTROL)
    emulated = RateTestSettings.of(cfg)
    assert emulated.truth == cfg.imu.errors
    assert set(scale_factor_document(emulated, [], "completed")["truth"]) == {"x", "y", "z"}
    real = RateTestSettings.of(cfg.model_copy(update={"imu": cfg.imu.model_copy(update={"source": "serial"})}))
    assert real.truth is None
    assert "truth" not in scale_factor_document(real, [], "completed")
    assert "truth" not in frequency_response_document(real, [], "completed")


def test_the_steps_and_the_document_take_the_tests_settings_from_the_settings():
    settings = RateTestSettings.of(load_config(ACUTROL))
    asked = FrequencyResponseSettings(frequencies_hz=[2.0, 4.0, 8.0], dwell_s=0.5, axes=["z"])
    replaced = dataclasses.replace(settings, frequency_response=asked)
    steps = frequency_steps(replaced, ("outer", "middle", "inner"))
    assert [s.frequency for s in steps] == [2.0, 4.0, 8.0] and {s.gyro for s in steps} == {2}
    doc = frequency_response_document(replaced, [], "completed")
    assert doc["settings"] == asked.model_dump() and doc["trial"]["name"] == settings.trial_name
    sf = ScaleFactorSettings(rates_dps=[10.0, 20.0], axes=["x"])
    assert scale_factor_document(dataclasses.replace(settings, scale_factor=sf), [], "completed")["settings"] \
        == sf.model_dump()
