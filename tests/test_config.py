import re
from importlib.resources import files
from pathlib import Path

import pytest

from hil.config import ConfigError, load_config, parse_config
from hil.inputs import resolve_path

MINIMAL = {"trial": {"duration_s": 10}, "site": {"latitude_deg": 32}}


def test_minimal_config_takes_documented_defaults():
    cfg = parse_config(MINIMAL)
    assert cfg.trial.rate_hz == 200
    assert cfg.imu.protocol == "kvh1750"
    assert cfg.imu.errors.accel_bias_ug == (0.0, 0.0, 0.0)


def test_wrong_vector_length_names_the_key_path():
    data = {**MINIMAL, "imu": {"errors": {"accel_bias_ug": [1, 2]}}}
    with pytest.raises(ConfigError, match=r"imu\.errors\.accel_bias_ug: expected 3 numbers, got 2"):
        parse_config(data)


def test_unknown_key_is_an_error():
    data = {**MINIMAL, "turntable": {"motoin": {}}}
    with pytest.raises(ConfigError, match=r"turntable\.motoin: unknown key"):
        parse_config(data)


def test_missing_required_key_is_named():
    with pytest.raises(ConfigError, match=r"site: required key is missing"):
        parse_config({"trial": {"duration_s": 1}})


def test_swing_axis_without_period_is_rejected():
    data = {**MINIMAL, "turntable": {"motion": {"axes": {"inner": {"amplitude_deg": 3}}}}}
    with pytest.raises(ConfigError, match=r"turntable\.motion\.axes\.inner: period_s is required"):
        parse_config(data)


def test_yaml_tags_are_not_executed(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("trial: !!python/object/apply:os.system ['true']\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(path)


@pytest.mark.parametrize("name", ["emulated_swing.yaml", "liu2019_sim.yaml", "lab_swing.yaml"])
def test_shipped_configs_validate(name):
    cfg = load_config(f"configs/{name}")
    assert cfg.turntable.motion.kind == "swing"


def test_resolve_path_takes_an_existing_path_then_the_shipped_file_else_the_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shipped = Path(files("hil.configs") / "emulated_swing.yaml")
    assert shipped.is_file() and not shipped.is_relative_to(tmp_path)
    assert resolve_path("configs/emulated_swing.yaml") == resolve_path("emulated_swing.yaml") == shipped
    (tmp_path / "configs").mkdir()
    (tmp_path / "configs" / "emulated_swing.yaml").write_text("trial: {}\n")
    assert resolve_path("configs/emulated_swing.yaml") == Path("configs/emulated_swing.yaml")
    for missing in ("configs/no_such_trial.yaml", "elsewhere/lab_swing.yaml"):
        assert resolve_path(missing) == Path(missing)


def test_faults_and_timing_are_off_by_default():
    cfg = parse_config(MINIMAL)
    for device in (cfg.imu, cfg.turntable):
        assert device.faults.drop_rate == 0 and device.faults.unplug_at_s is None
        assert device.timing.latch_jitter_us == 0 and not device.timing.free_running
    assert cfg.output.limits.bias_sigma_ug_max is None


def test_fault_rate_out_of_range_names_the_key_path():
    data = {**MINIMAL, "imu": {"faults": {"drop_rate": 1.5}}}
    with pytest.raises(ConfigError, match=r"imu\.faults\.drop_rate: Input should be less than or equal to 1"):
        parse_config(data)


@pytest.mark.parametrize("imu_rate, divider", [(200, 1), (1000, 5), (2000, 10), (600.0000000001, 3)])
def test_an_imu_rate_that_is_a_multiple_of_the_table_rate_gives_the_divider(imu_rate, divider):
    cfg = parse_config({**MINIMAL, "imu": {"rate_hz": imu_rate}})
    assert cfg.table_divider == cfg.table_counts_per_frame == divider
    assert cfg.table_counter_rate_hz == cfg.imu_rate_hz  # the table counts the pulse train


def test_a_free_running_table_counts_its_own_frames():
    cfg = parse_config({**MINIMAL, "imu": {"rate_hz": 1000}, "turntable": {"timing": {"free_running": True}}})
    assert (cfg.table_divider, cfg.table_counts_per_frame, cfg.table_counter_rate_hz) == (5, 1, 200.0)


@pytest.mark.parametrize("imu_rate", [300, 100, 1000.001])
def test_an_imu_rate_that_is_not_a_multiple_of_the_table_rate_is_rejected(imu_rate):
    with pytest.raises(ConfigError, match=r"imu\.rate_hz: .* not an integer multiple of trial\.rate_hz"):
        parse_config({**MINIMAL, "imu": {"rate_hz": imu_rate}})


@pytest.mark.parametrize(("imu_rate", "batch", "block"), [(None, None, 10), (1000, None, 50), (2000, None, 100),
                                                          (2000, 10, 10), (None, 1, 1)])
def test_the_estimator_takes_50_ms_of_samples_at_once_unless_batch_samples_says(imu_rate, batch, block):
    data = {**MINIMAL, "imu": {"rate_hz": imu_rate}, "estimator": {"batch_samples": batch}}
    assert parse_config(data).block_samples == block


def test_a_yaml_syntax_error_is_one_line_with_file_line_and_column(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("trial: {name: x, duration_s: 10\nsite: {latitude_deg: 32}\n")  # the brace is never closed
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    message = str(caught.value)
    assert "\n" not in message and re.match(rf"{re.escape(str(path))}:2:5: not valid YAML: ", message), message
