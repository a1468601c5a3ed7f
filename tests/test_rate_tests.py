"""The rate-table tests' emulated truth (scale asymmetry, low-pass, delay), the scale-factor and frequency-response
runs in simulation against it."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from pages import clipped_columns, layout_width, needs_chromium

from emulators.sensor_errors import SensorErrorModel
from emulators.sensor_response import continuous_response
from hil.cli import main
from hil.config import ConfigError, ImuErrors, load_config
from hil.config_ratetests import FrequencyResponseSettings, ScaleFactorSettings
from hil.trial.rate_steps import RateSequence
from hil.trial.ratetest_runner import run_frequency_response, run_scale_factor

RATE = 1000.0
T = 1.0 / RATE


def _gyro(errors: dict, dtheta: np.ndarray, chunks: int = 3) -> np.ndarray:
    """The gyro increments the error model makes of ideal ones (N, 3), fed in ``chunks`` pieces."""
    model = SensorErrorModel(ImuErrors(**errors), RATE, 1)
    t = np.arange(1, len(dtheta) + 1) * T
    parts = np.array_split(np.arange(len(t)), chunks)
    return np.vstack([model.apply(t[p], dtheta[p], np.zeros((len(p), 3)))[0] for p in parts])


def _phasor(x: np.ndarray, f: float) -> complex:
    """The complex amplitude of x at frequency f (least squares on cos, sin and a constant)."""
    k = np.arange(len(x)) * T * 2.0 * math.pi * f
    c = np.linalg.lstsq(np.column_stack([np.cos(k), np.sin(k), np.ones_like(k)]), x, rcond=None)[0]
    return complex(c[0], -c[1])


@pytest.mark.parametrize("f", [20.0, 100.0, 200.0])
@pytest.mark.parametrize("bandwidth, delay_ms", [(100.0, 2.5), (100.0, 0.0), (None, 1.3)])
def test_emulated_low_pass_and_delay_follow_the_continuous_transfer_function(f, bandwidth, delay_ms):
    rate = 0.5 * np.sin(2.0 * math.pi * f * np.arange(1, 6001) * T)  # rad/s, interval means
    out = _gyro({"bandwidth_hz": bandwidth, "damping": 0.7, "delay_ms": delay_ms}, np.outer(rate * T, np.ones(3)))
    ratio = _phasor(out[3000:, 1] / T, f) / _phasor(rate[3000:], f)
    truth = continuous_response(np.array([f]), bandwidth, 0.7, delay_ms * 1e-3)[0]
    assert abs(abs(ratio) / abs(truth) - 1.0) < 1e-3
    assert abs(math.degrees(np.angle(ratio / truth))) < 0.05


def test_emulated_low_pass_is_minus_3_db_at_its_bandwidth():
    rate = np.sin(2.0 * math.pi * 100.0 * np.arange(1, 6001) * T)
    out = _gyro({"bandwidth_hz": 100.0, "damping": 0.7}, np.outer(rate * T, np.ones(3)))
    gain_db = 20.0 * math.log10(abs(_phasor(out[3000:, 0], 100.0) / _phasor(rate[3000:] * T, 100.0)))
    assert gain_db == pytest.approx(-10.0 * math.log10(2.0), abs=0.01)


def test_emulated_delay_of_whole_periods_repeats_the_input_that_many_samples_later():
    rng = np.random.default_rng(3)
    dtheta = rng.normal(size=(500, 3)) * 1e-4
    out = _gyro({"delay_ms": 2.0}, dtheta, chunks=7)
    np.testing.assert_allclose(out[2:], dtheta[:-2], rtol=0, atol=1e-18)
    np.testing.assert_allclose(out[:2], dtheta[[0, 0]], rtol=0, atol=1e-18)  # at rest on the first sample before


def test_scale_asymmetry_scales_positive_and_negative_rates_apart():
    dtheta = np.array([[1.0, -1.0, 0.5], [-1.0, 1.0, -0.5]]) * T
    out = _gyro({"scale_asymmetry_ppm": [200.0, 200.0, 0.0], "gyro_scale_ppm": [100.0, 0.0, 0.0]}, dtheta, chunks=1)
    k_plus, k_minus = out[0, 0] / dtheta[0, 0], out[1, 0] / dtheta[1, 0]
    assert (k_plus - k_minus) / ((k_plus + k_minus) / 2.0) == pytest.approx(200e-6, rel=1e-9)
    assert (k_plus + k_minus) / 2.0 == pytest.approx(1.0 + 100e-6, rel=1e-12)
    assert out[0, 2] == dtheta[0, 2]


def test_emulated_bandwidth_beyond_a_tenth_of_the_rate_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"imu\.errors\.bandwidth_hz: 150 Hz"):
        SensorErrorModel(ImuErrors(bandwidth_hz=150.0), RATE, 0)


# --- the tests in simulation ----------------------------------------------------------------------------------------

ACUTROL = Path(__file__).resolve().parent.parent / "configs" / "ratetest_acutrol.yaml"
AEROSMITH = Path(__file__).resolve().parent.parent / "configs" / "rate_table_aerosmith.yaml"


def _config(tmp_path: Path, base: Path = ACUTROL, **blocks) -> Path:
    """``base`` with ``blocks`` merged one level deep, written to tmp_path."""
    doc = yaml.safe_load(base.read_text())
    for key, value in blocks.items():
        doc[key] = {**doc.get(key, {}), **value} if isinstance(value, dict) else value
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_scale_factor_test_finds_the_emulated_scale_factor_asymmetry_and_bias_within_3_sigma(tmp_path):
    cfg = load_config(_config(tmp_path))
    doc = run_scale_factor(cfg, ScaleFactorSettings(rates_dps=[60, 180], dwell_s=2, settle_s=0.2, axes=["x", "z"]))
    assert doc["ended"] == "completed" and sorted(doc["axes"]) == ["x", "z"]
    for axis, a in doc["axes"].items():
        truth = doc["truth"][axis]
        for key, sigma in (("scale_factor_ppm", "scale_factor_sigma_ppm"), ("bias_dph", "bias_sigma_dph"),
                           ("asymmetry_signed_ppm", "asymmetry_sigma_ppm")):
            assert abs(a[key] - truth[key]) < 3.0 * a[sigma], (axis, key, a[key], truth[key], a[sigma])
        assert a["nonlinearity_ppm"] < 4.0 * a["nonlinearity_sigma_ppm"]  # a linear gyro: its noise alone
        assert len(a["steps"]) == 4 and {s["rate_dps"] for s in a["steps"]} == {60.0, -60.0, 180.0, -180.0}


def test_scale_factor_test_input_rate_is_the_encoders_turn_plus_the_earths_rate_about_the_axis(tmp_path):
    cfg = load_config(_config(tmp_path, imu={"errors": {}}))
    doc = run_scale_factor(cfg, ScaleFactorSettings(rates_dps=[30, 90], dwell_s=1, settle_s=0.2, axes=["z"]))
    earth_dph = 15.041067 * math.sin(math.radians(32.0))  # the outer axis is vertical: Omega sin(latitude)
    for step in doc["axes"]["z"]["steps"]:
        assert (step["input_dps"] - step["rate_dps"]) * 3600.0 == pytest.approx(earth_dph, abs=1e-3)
        assert step["output_dps"] == pytest.approx(step["input_dps"], abs=1e-9)  # an ideal gyro reads its input
    assert abs(doc["axes"]["z"]["bias_dph"]) < 1e-5


def test_scale_factor_test_on_the_single_axis_aerosmith_table_tests_the_gyro_on_its_axis(tmp_path):
    cfg = load_config(_config(tmp_path, AEROSMITH, imu={"errors": {"gyro_bias_dph": [0.5, -0.3, 0.8],
                                                                   "gyro_noise_dph": [0.5, 0.5, 0.5],
                                                                   "gyro_scale_ppm": [0, 0, 400]}}))
    doc = run_scale_factor(cfg, ScaleFactorSettings(rates_dps=[20, 50], dwell_s=1, settle_s=0.2))
    assert list(doc["axes"]) == ["z"]
    z = doc["axes"]["z"]
    assert abs(z["scale_factor_ppm"] - 400.0) < 3.0 * z["scale_factor_sigma_ppm"]
    assert abs(z["bias_dph"] - 0.8) < 3.0 * z["bias_sigma_dph"]


def test_frequency_response_finds_the_emulated_bandwidth_damping_and_delay(tmp_path):
    cfg = load_config(_config(tmp_path))
    doc = run_frequency_response(cfg, FrequencyResponseSettings(frequencies_hz=[5, 20, 50, 80, 100, 150], dwell_s=0.2,
                                                                settle_s=0.1, axes=["y"]))
    y = doc["axes"]["y"]
    assert y["bandwidth_hz"] == pytest.approx(100.0, rel=0.05)
    assert y["delay_ms"] == pytest.approx(2.0, abs=0.1)
    assert y["damping"] == pytest.approx(0.7, abs=0.05)
    assert y["gain_db"][4] == pytest.approx(-3.01, abs=0.1)  # at the bandwidth
    assert y["latch_check"].startswith("disagrees: the gyro lags the encoder by 2.000 ms")  # 2 ms the config does not state


def test_frequency_response_of_an_imu_without_output_delay_agrees_with_the_stated_latch_delays(tmp_path):
    cfg = load_config(_config(tmp_path, imu={"rate_hz": 1000, "errors": {"bandwidth_hz": 100.0,
                                                                          "gyro_noise_dph": [3.0] * 3}}))
    doc = run_frequency_response(cfg, FrequencyResponseSettings(frequencies_hz=[5, 20, 50, 100, 150], dwell_s=0.2,
                                                                settle_s=0.1, axes=["z"]))
    assert abs(doc["axes"]["z"]["delay_ms"]) < 0.05
    assert doc["axes"]["z"]["latch_check"] == ("agrees with the latch delays stated (imu.latch_delay_us 0, "
                                               "turntable.latch_delay_us 0)")


def test_frequency_response_below_the_bandwidth_says_it_lies_beyond_the_highest_frequency(tmp_path):
    cfg = load_config(_config(tmp_path))
    doc = run_frequency_response(cfg, FrequencyResponseSettings(frequencies_hz=[2, 5, 10, 20, 30], dwell_s=0.5,
                                                                settle_s=0.1, axes=["x"]))
    x = doc["axes"]["x"]
    assert x["bandwidth_hz"] is None and x["bandwidth_note"] == "beyond the highest frequency tested (30 Hz)"
    assert x["damping"] is None and x["damping_sigma"] is None


def test_a_rate_beyond_the_tables_limit_exits_2_naming_the_key_and_limit_before_the_table_moves(tmp_path, capsys,
                                                                                                monkeypatch):
    commands = []
    monkeypatch.setattr(RateSequence, "start", lambda self: commands.append("start"))
    path = _config(tmp_path, scale_factor={"rates_dps": [90, 400]})
    assert main(["ratetest", "scale-factor", str(path), "--simulate", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("hil: error: scale_factor.rates_dps: 400 deg/s is beyond turntable.limits.rate_dps of the outer "
                   "axis (300 deg/s); nothing was sent")
    assert not commands and not (tmp_path / "out" / "scale_factor.json").exists()


def test_a_frequency_the_tables_acceleration_limit_cannot_serve_exits_2_naming_the_key(tmp_path, capsys):
    path = _config(tmp_path, turntable={"limits": {"rate_dps": [300, 100, 100], "accel_dps2": [500, 200, 200]}},
                   frequency_response={"frequencies_hz": [10, 100, 150]})
    assert main(["ratetest", "frequency-response", str(path), "--simulate", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "frequency_response.frequencies_hz: 100 Hz: turntable.limits.accel_dps2 of the outer axis (500" in err


def test_the_shipped_aerosmith_config_runs_its_scale_factor_test_within_its_tables_limits(tmp_path):
    out = tmp_path / "out"
    assert main(["ratetest", "scale-factor", "rate_table_aerosmith.yaml", "--simulate", "--out", str(out)]) == 0
    z = json.loads((out / "scale_factor.json").read_text())["axes"]["z"]
    assert abs(z["bias_dph"] - 0.8) < 3.0 * z["bias_sigma_dph"]


def test_ratetest_command_fails_a_scale_factor_beyond_its_limit_in_report_and_junit(tmp_path):
    path = _config(tmp_path, scale_factor={"rates_dps": [90, 180], "dwell_s": 1, "settle_s": 0.2, "axes": ["x"]},
                   output={"limits": {"scale_factor_ppm_max": 250, "asymmetry_ppm_max": 200}})
    out = tmp_path / "out"
    assert main(["ratetest", "scale-factor", str(path), "--simulate", "--out", str(out)]) == 3  # x: 300 ppm
    junit = ET.parse(out / "junit.xml").getroot()
    failed = {case.get("name") for case in junit.iter("testcase") if case.find("failure") is not None}
    assert failed == {"scale_factor_error_x"}
    assert json.loads((out / "scale_factor.json").read_text())["record"]["config_sha256"]
    assert (out / "config.yaml").read_text() == path.read_text()
    assert "FAIL" in (out / "report.html").read_text() and (out / "scale_factor.png").exists()


def test_ratetest_files_the_test_in_the_history_with_each_gyros_figures(tmp_path):
    from hil.history.store import History

    path = _config(tmp_path, scale_factor={"rates_dps": [90, 180], "dwell_s": 1, "settle_s": 0.2, "axes": ["z"]})
    history = tmp_path / "history.sqlite"
    assert main(["ratetest", "scale-factor", str(path), "--simulate", "--out", str(tmp_path / "out"), "--no-figures",
                 "--dut", "SN-7", "--history", str(history)]) == 0
    [row] = History(str(history)).trials("SN-7")
    assert row["kind"] == "scale_factor" and row["verdict"] == "PASS"
    assert abs(row["figures"]["z.scale_factor_ppm"] - 150.0) < 3.0 * row["figures"]["z.scale_factor_sigma_ppm"]


def test_emulated_gyro_range_clips_its_output():
    dtheta = np.array([[3.0, -3.0, 1.0]]) * T  # rad/s
    out = _gyro({"gyro_range_dps": math.degrees(2.0)}, dtheta, chunks=1)
    np.testing.assert_allclose(out[0] / T, [2.0, -2.0, 1.0], rtol=1e-12)


def test_steps_at_the_gyros_range_are_left_out_of_the_fit_and_named_in_the_report(tmp_path):
    path = _config(tmp_path, imu={"errors": {**yaml.safe_load(ACUTROL.read_text())["imu"]["errors"],
                                             "gyro_range_dps": 150.0}},
                   scale_factor={"rates_dps": [30, 90, 180], "dwell_s": 1, "settle_s": 0.2, "axes": ["x"],
                                 "gyro_range_dps": 150.0})
    out = tmp_path / "out"
    assert main(["ratetest", "scale-factor", str(path), "--simulate", "--out", str(out), "--no-figures"]) == 0
    x = json.loads((out / "scale_factor.json").read_text())["axes"]["x"]
    left = {s["rate_dps"]: s["left_out"] for s in x["steps"] if s["saturated"]}
    assert left == {180.0: "the gyro reads its range, 150 deg/s (scale_factor.gyro_range_dps)",
                    -180.0: "the gyro reads its range, 150 deg/s (scale_factor.gyro_range_dps)"}
    assert abs(x["scale_factor_ppm"] - 300.0) < 3.0 * x["scale_factor_sigma_ppm"]  # from the steps below the range
    assert "steps_left_out_x" in (out / "report.html").read_text()


@needs_chromium
def test_the_scale_factor_report_fits_1400_px_without_a_clipped_column(tmp_path):
    path = _config(tmp_path, imu={"errors": {**yaml.safe_load(ACUTROL.read_text())["imu"]["errors"],
                                             "gyro_range_dps": 150.0}},
                   scale_factor={"rates_dps": [30, 90, 180], "dwell_s": 1, "settle_s": 0.2, "axes": ["x", "y"],
                                 "gyro_range_dps": 150.0})
    out = tmp_path / "out"
    assert main(["ratetest", "scale-factor", str(path), "--simulate", "--out", str(out)]) == 0
    assert layout_width(out / "report.html", tmp_path) <= 1400
    assert clipped_columns(out / "report.html", tmp_path) == []


def test_a_negative_rate_in_the_settings_is_refused_naming_its_key(tmp_path, capsys):
    path = _config(tmp_path, scale_factor={"rates_dps": [30, -90]})
    assert main(["ratetest", "scale-factor", str(path), "--simulate", "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.strip().endswith("scale_factor.rates_dps[1]: Input should be greater than 0")


def test_simulating_a_config_that_reads_devices_is_refused_naming_the_key(tmp_path, capsys):
    path = _config(tmp_path, imu={"source": "serial", "port": "/dev/ttyUSB0"})
    assert main(["ratetest", "scale-factor", str(path), "--simulate", "--out", str(tmp_path / "out")]) == 2
    assert "imu.source: serial: hil ratetest --simulate emulates the devices" in capsys.readouterr().err
    assert not (tmp_path / "out" / "scale_factor.json").exists()


@pytest.mark.parametrize("table_gate, runs", [(True, 3), (False, 1)])
def test_without_the_gyro_table_gate_a_gyro_lagging_the_table_keeps_every_sample(table_gate, runs):
    from hil.frames import Earth, TableGeometry
    from hil.pipeline.judge import Judge
    from hil.samples import AlignedBatch

    judge = Judge(Earth.from_degrees(32.0), TableGeometry(), 200.0, 100.0, table_gate=table_gate)
    t = np.arange(1, 21) / 200.0
    angles = np.zeros((20, 3))
    angles[:, 0] = np.radians(10.0) * t  # 10 deg/s about the outer axis
    dtheta = np.zeros((20, 3))
    dtheta[:, 2] = np.radians(10.0) / 200.0
    dtheta[10, 2] *= 0.5  # one sample lagging the table by half its turn
    first = judge.gated(AlignedBatch(t[:1], dtheta[:1], np.zeros((1, 3)), angles[:1], 0.0))
    gated = judge.gated(AlignedBatch(t[1:], dtheta[1:], np.zeros((19, 3)), angles[1:], t[0]))
    assert len(first) == 1 and len(gated) == runs  # gated: the runs before and after it, and its gap


def test_a_frequency_the_tables_angle_reports_cannot_follow_exits_2_naming_the_key(tmp_path, capsys):
    path = _config(tmp_path, trial={"rate_hz": 200}, frequency_response={"frequencies_hz": [10, 20, 50]})
    assert main(["ratetest", "frequency-response", str(path), "--simulate", "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.strip() == (
        "hil: error: frequency_response.frequencies_hz: 50 Hz: the table reports its angles at trial.rate_hz (200 Hz), "
        "fewer than 5 a cycle; nothing was sent")
