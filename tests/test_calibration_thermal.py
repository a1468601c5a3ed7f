"""The calibration over temperature: a soak at each chamber set point judged on the IMU's own temperature, the
multi-position calibration at each, every term's polynomial in temperature fitted with its sigma, and
calibration.json's ``thermal`` applied at each sample's temperature."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from pages import clipped_columns, layout_width, needs_chromium

from drivers.watlow_f4 import ChamberError
from emulators.chamber import ChamberModel, chamber_model
from emulators.servo_simulation import ServoSimulation
from hil.cli import main
from hil.config import load_config
from hil.config_environment import SoakSettings
from hil.estimation.calibration_model import TERMS, Window
from hil.estimation.thermal_calibration import fit_polynomial
from hil.outputs.calibration_report import BLOCKS
from hil.outputs.calibration_thermal import thermal_document
from hil.pipeline.compensation import Compensation
from hil.samples import ImuSamples
from hil.trial.calibration_soak import Soak
from hil.trial.calibration_thermal import window_temperatures
from hil.units import UG

ROOT = Path(__file__).resolve().parents[1]
THERMAL = ROOT / "configs" / "calibration_thermal_quick.yaml"


def _config(tmp_path: Path, name: str, change) -> Path:
    cfg = yaml.safe_load(THERMAL.read_text())
    change(cfg)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> Path:
    """``hil calibrate configs/calibration_thermal_quick.yaml --simulate``: its output directory."""
    out = tmp_path_factory.mktemp("thermal") / "out"
    assert main(["calibrate", str(THERMAL), "--simulate", "--out", str(out), "--viewer", "none"]) == 0
    return out


def test_a_calibration_over_three_temperatures_fits_every_thermal_term_within_4_sigma_of_the_truth(calibrated):
    doc = json.loads((calibrated / "calibration.json").read_text())
    thermal, truth = doc["thermal"], doc["truth"]["thermal"]["terms"]
    assert [t["set_point_c"] for t in thermal["temperatures"]] == [-10, 25, 60]
    # the soak waited for the sensor: 2 deg C of self-heating above the chamber's air
    assert [round(t["imu_c"], 1) for t in thermal["temperatures"]] == [-8.0, 27.0, 62.0]
    assert thermal["reference_c"] == 27.0 and thermal["order"] == 2 and len(thermal["terms"]) == 12
    errors = {name: [(c - t) / s for c, s, t in zip(term["coefficients"], term["sigma"], truth[name], strict=True)]
              for name, term in thermal["terms"].items()}
    assert all(abs(e) <= 4.0 for values in errors.values() for e in values), errors
    # the accelerometers' first-order coefficient, 4 ug/deg C on x, to within a few percent
    assert thermal["terms"]["accel.bias_ug.0"]["coefficients"][1] == pytest.approx(4.0 + 2 * 0.05 * 2.0, abs=0.1)
    assert doc["accel"]["bias_ug"][0] == thermal["terms"]["accel.bias_ug.0"]["coefficients"][0]
    assert len(doc["positions"]) == 18 and {p["temperature_c"] for p in doc["positions"]} == {
        t["imu_c"] for t in thermal["temperatures"]}


def test_a_simulated_soak_makes_no_imu_samples_and_settles_when_the_sampled_one_did(calibrated):
    """--simulate's soaks move the chamber and the sensor's temperature on block by block without the IMU's
    samples: each ends at the trial time the soaks made sample by sample ended at, and only the schedules'
    samples are made."""
    doc = json.loads((calibrated / "calibration.json").read_text())
    assert [t["soak_s"] for t in doc["thermal"]["temperatures"]] == [16.176, 46.416, 46.416]
    assert [t["imu_c"] for t in doc["thermal"]["temperatures"]] == pytest.approx(
        [-8.000385839886548, 26.9988210025391, 61.99882100253908], abs=1e-12)
    result = json.loads((calibrated / "result.json").read_text())
    assert result["streams"]["imu_frames"] == 53064  # 80316 with the soaks' samples made


def test_an_unsampled_soak_sees_the_temperatures_and_table_the_samples_would_carry():
    """configs/calibration_thermal.yaml (six set points, -40 to 70 deg C): block by block, ServoSimulation.idle
    gives the temperatures step's samples carry, and its gap ends at the table's reading of the last sample."""
    cfg = load_config(ROOT / "configs" / "calibration_thermal.yaml")
    assert cfg.calibration.temperatures_c == [-40, -18, 4, 26, 48, 70]
    sims = [ServoSimulation.from_config(cfg) for _ in range(2)]
    for sim in sims:
        model = chamber_model(cfg.environment.chamber)
        model.set_point_c = 70.0
        sim.errors.follow_chamber(model.advance)
    sampled, idle = sims
    for k in range(1, 201):
        batch = sampled.step(k * 0.05)
        assert np.array_equal(idle.idle(k * 0.05), batch.temperature_c)
    assert idle.samples == sampled.samples == 2500 and batch.temperature_c[-1] > -39.99
    gap = idle.gap(0.0)
    assert (gap.t_start, gap.t_end) == (0.0, 10.0) and gap.angles_end == tuple(batch.angles[-1])


def test_calibration_html_shows_every_thermal_term_with_its_fit(calibrated):
    page = (calibrated / "calibration.html").read_text()
    section = page[page.index("<h2>Over temperature</h2>"):]
    assert section.count("<tr><td>accel.bias_ug.") == 3 and section.count("<tr><td>gyro.scale_ppm.") == 3
    assert 'alt="terms against temperature" src="data:image/png;base64,' in section


@needs_chromium
def test_calibration_html_over_temperature_stays_within_a_lab_window(calibrated, tmp_path):
    assert layout_width(calibrated / "calibration.html", tmp_path) <= 1400
    assert not clipped_columns(calibrated / "calibration.html", tmp_path)


def _swing(tmp_path: Path, calibration: Path | None) -> dict:
    """A simulated swing at 40 deg C (between the calibration's 25 and 60) with ``calibration`` applied: its
    result.json."""

    def change(cfg: dict) -> None:
        cfg["trial"].update(duration_s=60, name="swing-40")
        cfg["turntable"].pop("command_port")
        cfg["turntable"]["motion"] = {"kind": "swing", "axes": {
            "outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
            "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
            "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6}}}
        cfg["imu"]["errors"]["temperature_c"] = cfg["environment"]["chamber"]["set_point_c"] = 40.0
        if calibration is not None:
            cfg["imu"]["calibration"] = str(calibration)
        del cfg["calibration"], cfg["output"]

    name = "calibrated" if calibration else "raw"
    out = tmp_path / name
    assert main(["simulate", str(_config(tmp_path, name, change)), "--out", str(out), "--viewer", "none",
                 "--no-figures"]) == 0
    return json.loads((out / "result.json").read_text())


def test_a_swing_between_the_calibration_temperatures_sees_the_bias_calibrated_away(calibrated, tmp_path):
    doc = json.loads((calibrated / "calibration.json").read_text())
    raw, calibrated_run = _swing(tmp_path, None), _swing(tmp_path, calibrated / "calibration.json")
    assert min(abs(b) for b in raw["estimate"]["accel_bias_ug"]) > 100.0  # uncalibrated: the bias at 42 deg C
    assert calibrated_run["calibration_applied"]["thermal"]["terms"][0] == "accel.bias_ug.0"
    for k, (bias, sigma) in enumerate(zip(calibrated_run["estimate"]["accel_bias_ug"],
                                          calibrated_run["estimate"]["accel_bias_sigma_ug"], strict=True)):
        # the calibration's own sigma at 42 deg C: within that of its constant and first-order terms
        term = doc["thermal"]["terms"][f"accel.bias_ug.{k}"]["sigma"]
        combined = np.hypot(sigma, term[0] + term[1] * 15.0 + term[2] * 15.0 ** 2)
        assert abs(bias) <= 3.0 * combined, (k, bias, combined)


def test_a_thermal_calibration_file_is_applied_at_each_samples_own_temperature(tmp_path):
    """A bias of 100 + 5 dT ug on x about 20 deg C: samples at 20 and 30 deg C come out with the bias of their
    own temperature taken away, a sample without a temperature with the reference's."""
    doc = {"accel": {"bias_ug": [100.0, 0, 0], "scale_ppm": [0, 0, 0], "misalignment_arcsec": [0] * 6,
                     "nonlinearity_ug_per_g2": [0, 0, 0]},
           "gyro": {"bias_dph": [0, 0, 0], "scale_ppm": [0, 0, 0], "misalignment_arcsec": [0] * 6},
           "thermal": {"reference_c": 20.0, "order": 1,
                       "terms": {"accel.bias_ug.0": {"coefficients": [100.0, 5.0], "sigma": [1.0, 0.1]}}}}
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(doc))
    period = 0.01
    bias = np.array([100.0, 150.0, 100.0]) * UG
    samples = ImuSamples(np.arange(3), np.zeros((3, 3)), np.column_stack([bias * period, np.zeros(3), np.zeros(3)]),
                         np.zeros(3), np.zeros(3, dtype=np.int64), np.array([20.0, 30.0, np.nan]))
    out = Compensation(path, period).samples(samples)
    assert np.max(np.abs(out.dv)) < 1e-15


def test_a_thermal_order_the_temperatures_cannot_hold_is_refused_naming_the_key(tmp_path, capsys):
    path = _config(tmp_path, "order", lambda cfg: cfg["calibration"].update(temperatures_c=[-10, 60]))
    assert main(["calibrate", str(path), "--simulate", "--out", str(tmp_path / "out"), "--viewer", "none"]) == 2
    err = capsys.readouterr().err.strip()
    assert "calibration.thermal_order: a polynomial of order 2 needs at least 3 different temperatures" in err
    assert len(err.splitlines()) == 1


def test_a_calibration_temperature_beyond_the_chambers_limits_is_refused_naming_it(tmp_path, capsys):
    path = _config(tmp_path, "limits", lambda cfg: cfg["environment"]["chamber"].update(limits_c=[-20, 50]))
    assert main(["calibrate", str(path), "--simulate", "--out", str(tmp_path / "out"), "--viewer", "none"]) == 2
    assert "calibration.temperatures_c[2]: 60 deg C is outside environment.chamber.limits_c [-20, 50]" in \
        capsys.readouterr().err


def test_a_polynomial_through_noisy_points_has_the_sigma_of_its_least_squares():
    temperatures, sigmas = np.array([-10.0, 25.0, 60.0, 80.0]), np.array([1.0, 2.0, 1.0, 4.0])
    values = 3.0 + 0.5 * (temperatures - 25.0)
    coefficients, sigma = fit_polynomial(temperatures, values, sigmas, 1, 25.0)
    assert coefficients == pytest.approx([3.0, 0.5], abs=1e-12)
    design = np.column_stack([np.ones(4), temperatures - 25.0])
    expected = np.sqrt(np.diag(np.linalg.inv(design.T @ np.diag(sigmas**-2) @ design)))
    assert sigma == pytest.approx(expected, rel=1e-12)  # residuals zero: never shrunk below the points' sigmas


class _Chamber:
    """A chamber controller over a :class:`ChamberModel` whose time the test moves on."""

    def __init__(self, model: ChamberModel) -> None:
        self.model = model

    def temperature_c(self) -> float:
        return round(self.model.temperature_c, 1)

    def set_set_point_c(self, value: float) -> None:
        self.model.set_point_c = value


def _soak(model: ChamberModel, imu, seconds: float, settings: SoakSettings) -> Soak:
    """A soak to 40 deg C fed every 0.1 s for ``seconds``, the IMU at ``imu(t)``."""
    soak = Soak(40.0, settings, _Chamber(model), 0.0)
    for t in np.arange(0.1, seconds, 0.1):
        model.advance(t)
        soak.update(float(t), imu(t))
        if soak.done or soak.failure:
            break
    return soak


def test_a_soak_waits_for_the_imus_own_temperature_not_the_chamber():
    settings = SoakSettings(stable_within_c=0.05, for_s=5, timeout_s=200, stalled_s=20)
    model = ChamberModel(1.0, 100.0, 40.0)  # the chamber there already
    soak = _soak(model, lambda t: 40.0 - 15.0 * np.exp(-t / 10.0), 200.0, settings)
    # 15 exp(-t/10) moves less than 0.05 deg C over 5 s from t = 10 ln(15 (1 - e^-0.5) / 0.05) = 47.6 s
    assert soak.done and 52.0 <= soak.took_s <= 54.0


def test_a_soak_that_does_not_settle_ends_naming_the_temperatures_seen():
    settings = SoakSettings(stable_within_c=0.05, for_s=5, timeout_s=30, stalled_s=20)
    soak = _soak(ChamberModel(1.0, 100.0, 40.0), lambda t: 20.0 + 0.1 * t, 100.0, settings)
    assert not soak.done and soak.failure.startswith("soak at 40 deg C: not stable within 30 s "
                                                     "(calibration.soak.timeout_s): the chamber at 40.0 deg C, "
                                                     "the IMU at 23.")


def test_a_chamber_that_stops_changing_far_from_its_set_point_ends_the_soak_as_a_heater_fault():
    settings = SoakSettings(stable_within_c=0.05, for_s=5, timeout_s=300, stalled_s=20)
    model = ChamberModel(2.0, 60.0, 0.0, fault_at_s=10.0)  # ramping at 1 deg C/s, then held at 10 deg C
    soak = _soak(model, lambda t: 5.0, 300.0, settings)
    assert soak.failure == ("soak at 40 deg C: the chamber's reading held at 10.0 deg C for 20 s "
                            "(calibration.soak.stalled_s), 30.0 deg C from its set point: a heater or cooling fault "
                            "of environment.chamber")
    assert model.t < 32.0  # at once, not at the timeout


def test_a_simulated_calibration_whose_chamber_heater_fails_ends_early_naming_it(tmp_path):
    path = _config(tmp_path, "fault", lambda cfg: cfg["environment"]["chamber"].update(heater_fault_at_s=60.0))
    out = tmp_path / "out"
    assert main(["calibrate", str(path), "--simulate", "--out", str(out), "--viewer", "none", "--no-figures"]) == 1
    ended = json.loads((out / "result.json").read_text())["ended"]
    assert "soak at 25 deg C: the chamber's reading held at" in ended and "heater" in ended
    assert not (out / "calibration.json").exists()


def test_a_chamber_that_stops_answering_during_a_soak_ends_it_naming_the_chamber():
    class Silent(_Chamber):
        def temperature_c(self) -> float:
            raise ChamberError("chamber at /dev/ttyUSB1: read register 100: no response")

    soak = Soak(40.0, SoakSettings(), Silent(ChamberModel(1.0, 100.0, 40.0)), 0.0)
    soak.update(1.0, 25.0)
    assert soak.failure == ("soak at 40 deg C: environment.chamber: chamber at /dev/ttyUSB1: read register 100: "
                            "no response") and not soak.done


def test_an_emulated_calibration_over_temperature_at_full_speed_sets_the_emulated_chamber_over_modbus(tmp_path):
    """The live path: hil emulate's chamber (an F4 on a pty) set through the watlow-f4 driver at each temperature."""
    from test_lab_thermal import quick_config

    cfg = quick_config()
    path = tmp_path / "quick.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    assert main(["calibrate", str(path), "--speed", "max", "--out", str(out), "--viewer", "none", "--quiet",
                 "--no-figures"]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    temperatures = doc["thermal"]["temperatures"]
    assert [(t["set_point_c"], t["chamber_c"]) for t in temperatures] == [(20, 20.0), (25, 25.0), (30, 30.0)]
    assert [round(t["imu_c"]) for t in temperatures] == [22, 27, 32]  # the KVH's whole degrees, self-heated
    truth = doc["truth"]["thermal"]["terms"]
    assert all(abs(c - t) <= 4.0 * s for name, term in doc["thermal"]["terms"].items()
               for c, s, t in zip(term["coefficients"], term["sigma"], truth[name], strict=True))


def test_a_calibration_over_temperature_without_a_chamber_is_refused_naming_the_key(tmp_path, capsys):
    path = _config(tmp_path, "no-chamber", lambda cfg: cfg.pop("environment"))
    assert main(["calibrate", str(path), "--simulate", "--out", str(tmp_path / "out"), "--viewer", "none"]) == 2
    assert "calibration.temperatures_c: a calibration over temperature needs environment.chamber" in \
        capsys.readouterr().err


def test_a_soak_on_an_imu_that_reports_no_temperature_ends_naming_it_not_at_the_timeout():
    settings = SoakSettings(stable_within_c=0.05, for_s=5, timeout_s=3600, stalled_s=20)
    soak = _soak(ChamberModel(1.0, 100.0, 40.0), lambda t: None, 3600.0, settings)
    assert soak.failure == ("soak at 40 deg C: the IMU reported no temperature in the last 5 s (calibration.soak."
                            "for_s): a calibration over temperature needs an IMU whose frames carry it")
    assert soak.chamber_readings[-1][0] < 7.0


def test_a_window_stands_at_its_own_temperature_and_a_scale_factor_at_its_plateaus():
    """The sensor warming 0.01 deg C/s through a schedule: the dwells, every window and each gyro axis's plateaus
    (weighted by their samples times the squared rate on the axis) each at their own mean temperature."""
    t = np.arange(1.0, 51.0)
    trace = np.column_stack([t, 20.0 + 0.01 * (t - 0.5)])  # each read's mean, ending at t
    trace = np.vstack([trace[:10], trace[9], trace[10:]])  # an event at 10 s repeating the last read
    spans = [(2.0, 6.0), (8.0, 12.0), (14.0, 18.0), (30.0, 34.0), (40.0, 44.0)]
    turns = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.5, 0.0, 0.0), (0.0, 0.0, 0.5), (0.0, 0.0, -1.0)]
    windows = [Window(np.zeros((1, 3)), np.array(w), np.zeros(3), np.array(w), 400, 4.0) for w in turns]
    seen = window_temperatures(trace, spans, windows)
    every = 20.0 + 0.01 * np.mean([4.0, 10.0, 16.0, 32.0, 42.0])
    assert seen["dwells_c"] == pytest.approx(20.07, abs=1e-12)
    assert seen["windows_c"] == pytest.approx(every, abs=1e-12)
    assert seen["gyro_scale_c"] == pytest.approx([20.16, every, 20.0 + 0.01 * (0.25 * 32 + 42) / 1.25], abs=1e-12)


def _calibration(gyro_scale: list[float], accel_bias: list[float]) -> dict:
    """A calibration at one temperature (calibration.json's form) knowing the gyros' scale factors (sigma 0.01 ppm)
    and the accelerometers' biases (sigma 1 ug) alone."""
    doc = {"sigma": {}, "unobservable": {}, "positions": [],
           "turntable": {"zero_offset_arcsec": [None] * 3, "zero_offset_sigma_arcsec": [None] * 3}}
    for block, keys in BLOCKS:
        doc[block], doc["sigma"][block] = {}, {}
        for key, part, _ in keys:
            doc[block][key], doc["sigma"][block][key] = [None] * len(TERMS[part]), [None] * len(TERMS[part])
    doc["gyro"]["scale_ppm"], doc["sigma"]["gyro"]["scale_ppm"] = gyro_scale, [0.01] * 3
    doc["accel"]["bias_ug"], doc["sigma"]["accel"]["bias_ug"] = accel_bias, [1.0] * 3
    return doc


def test_each_thermal_term_is_fitted_at_the_temperature_of_the_windows_that_estimate_it():
    """A sensor still warming through each schedule: the gyros' scale factors measured on plateaus 0.01-0.09 deg C
    above the schedule's mean, the accelerometers' biases on dwells below it. Each polynomial through its terms at
    their own windows' temperatures is the truth (scale 100 + 2 dT ppm, bias 50 + 3 dT ug about 40 deg C); at the
    schedules' means it would be 0.1 ppm, ten sigma, off."""
    points, documents = [], []
    for k, imu_c in enumerate((20.0, 40.0, 60.0)):
        plateaus = [imu_c + 0.01 * (k + 1) * axis for axis in (1, 2, 3)]
        dwells = imu_c - 0.02 * (k + 1)
        points.append({"set_point_c": imu_c - 2.0, "chamber_c": imu_c - 2.0, "soak_s": 100.0, "imu_c": imu_c,
                       "dwells_c": dwells, "windows_c": imu_c, "gyro_scale_c": plateaus})
        documents.append(_calibration([100.0 + 2.0 * (c - 40.0) for c in plateaus], [50.0 + 3.0 * (dwells - 40.0)] * 3))
    terms = thermal_document(1, points, documents)["thermal"]["terms"]
    assert set(terms) == {f"{name}.{i}" for name in ("gyro.scale_ppm", "accel.bias_ug") for i in range(3)}
    for i in range(3):
        assert terms[f"gyro.scale_ppm.{i}"]["coefficients"] == pytest.approx([100.0, 2.0], abs=1e-9)
        assert terms[f"accel.bias_ug.{i}"]["coefficients"] == pytest.approx([50.0, 3.0], abs=1e-9)
