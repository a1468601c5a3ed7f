"""``hil noise`` on its three kinds of source: a simulated config, a recording replayed, its CSV export."""

from __future__ import annotations

import json
import math
import sqlite3

import numpy as np
import pytest
import yaml

from hil.cli import main

WHITE_DPH = 0.02  # gyro white noise, 1-sigma per sample
WALK_UG = 40.0  # accelerometer white noise, 1-sigma per sample


def _static(tmp_path, duration=2000.0, rate=50.0, source="emulator"):
    data = yaml.safe_load(open("configs/emulated_swing.yaml"))
    data["trial"].update(duration_s=duration, rate_hz=rate, name="static-noise")
    data["turntable"]["motion"] = {"kind": "static"}
    data["output"] = {}  # a static trial cannot meet the swing's bias limits
    data["imu"]["errors"] = {"gyro_noise_dph": [WHITE_DPH] * 3, "accel_noise_ug": [WALK_UG] * 3,
                             "gyro_random_walk_dph_per_sqrt_h": [2.0] * 3}
    path = tmp_path / "static.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_simulated_static_trial_gives_the_configured_white_noise_and_random_walk(tmp_path, capsys):
    rate = 50.0
    assert main(["noise", str(_static(tmp_path, rate=rate)), "--out", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "noise.json").read_text())
    assert doc["source"] == "simulation" and doc["motion_removed"] is False
    # white rate noise sigma per sample -> ARW = sigma sqrt(T) (deg/h sqrt(s)), / 60 for deg/sqrt(h)
    arw = WHITE_DPH * math.sqrt(1.0 / rate) / 60.0
    vrw = WALK_UG * 9.80665e-6 * math.sqrt(1.0 / rate) * 60.0
    lower, upper = doc["ci"]["gyro"]["arw_deg_per_sqrt_h"]["lower"], doc["ci"]["gyro"]["arw_deg_per_sqrt_h"]["upper"]
    for k in range(3):
        assert doc["gyro"]["arw_deg_per_sqrt_h"][k] == pytest.approx(arw, rel=0.05)
        assert lower[k] <= arw <= upper[k] or abs(doc["gyro"]["arw_deg_per_sqrt_h"][k] / arw - 1) < 0.02
        assert doc["accel"]["vrw_m_per_s_per_sqrt_h"][k] == pytest.approx(vrw, rel=0.05)
        assert doc["gyro"]["rrw_deg_per_h_per_sqrt_h"][k] == pytest.approx(2.0, rel=0.6)
    assert (tmp_path / "out" / "allan.png").stat().st_size > 0
    page = (tmp_path / "out" / "report.html").read_text()
    assert "Noise characterisation" in page and "data:image/png;base64," in page
    assert "gyro arw_deg_per_sqrt_h" in capsys.readouterr().out


@pytest.mark.slow
def test_a_recorded_trial_and_its_csv_export_give_identical_terms(tmp_path):
    config = _static(tmp_path, duration=60.0, rate=200.0)
    run = tmp_path / "run"
    assert main(["run", str(config), "--speed", "max", "--quiet", "--viewer", "none", "--no-figures",
                 "--out", str(run)]) == 0
    csv_path = tmp_path / "increments.csv"
    assert main(["noise", str(run), "--out", str(tmp_path / "n1"), "--export", str(csv_path), "--no-figures"]) == 0
    assert main(["noise", str(csv_path), "--out", str(tmp_path / "n2"), "--no-figures"]) == 0
    recorded, exported = (json.loads((tmp_path / d / "noise.json").read_text()) for d in ("n1", "n2"))
    assert recorded["source"] == "recording" and exported["source"] == "csv"
    for sensor in ("gyro", "accel"):
        assert recorded[sensor] == exported[sensor]
    assert recorded["samples"] == exported["samples"] == 12000
    arw = WHITE_DPH * math.sqrt(1.0 / 200.0) / 60.0
    assert np.allclose(recorded["gyro"]["arw_deg_per_sqrt_h"], arw, rtol=0.1)


def test_bad_sources_get_one_line(tmp_path, capsys):
    short = tmp_path / "short.csv"
    rows = ["t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps"]
    rows += [f"{k * 0.01},{1e-7 * k},0,0,0,0,0.098" for k in range(1, 11)]
    short.write_text("\n".join(rows) + "\n")
    assert main(["noise", str(short), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "short.csv" in err and "record a longer trial" in err

    moving = tmp_path / "moving.csv"
    t = np.arange(1, 2001) * 0.01
    rate = 0.3 * np.sin(2 * np.pi * t / 8.0)  # rad/s: a swing, without table angles
    rows = ["t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps"]
    rows += [f"{ti},{r * 0.01},0,0,0,0,0.098" for ti, r in zip(t, rate)]
    moving.write_text("\n".join(rows) + "\n")
    assert main(["noise", str(moving), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no table angles" in err


def test_a_shipped_config_run_from_elsewhere_has_its_digest_and_its_trial_name(tmp_path, monkeypatch,
                                                                              history_in_tmp):
    """The config named as shipped (not a path from the working directory) is the file the record digests, and
    the page and the history name the trial by its trial.name, not by the file."""
    import hashlib

    from hil.inputs import resolve_path

    monkeypatch.chdir(tmp_path)
    assert main(["noise", "emulated_swing.yaml", "--out", "out", "--no-figures", "--taus", "decade"]) == 0
    doc = json.loads((tmp_path / "out" / "noise.json").read_text())
    shipped = resolve_path("emulated_swing.yaml").read_bytes()
    assert doc["record"]["config_sha256"] == hashlib.sha256(shipped).hexdigest()
    assert doc["trial"] == {"name": "emulated-swing"}
    assert "<h1>emulated-swing</h1>" in (tmp_path / "out" / "report.html").read_text()
    with sqlite3.connect(history_in_tmp) as db:
        assert db.execute("SELECT name, config_sha256 FROM trials").fetchall() == [
            ("emulated-swing", doc["record"]["config_sha256"])]


def test_detrend_linear_takes_the_ramp_out_and_says_so(tmp_path):
    """A gyro ramp of 20 deg/h/h over white noise and random walk: fitted as the ramp term without --detrend;
    with --detrend linear removed first, its slope in noise.json's detrend and the ramp term null with the
    reason, the white term within 5 %."""
    config = _static(tmp_path, duration=2000.0, rate=50.0)
    data = yaml.safe_load(config.read_text())
    data["imu"]["errors"]["gyro_drift_dph_per_h"] = [20.0, -20.0, 20.0]
    config.write_text(yaml.safe_dump(data))
    docs = {}
    for detrend in ("none", "linear"):
        assert main(["noise", str(config), "--out", str(tmp_path / detrend), "--no-figures", "--no-history",
                     "--detrend", detrend]) == 0
        docs[detrend] = json.loads((tmp_path / detrend / "noise.json").read_text())
    kept, taken = docs["none"], docs["linear"]
    assert kept["detrend"] == {"kind": "none"}
    assert kept["gyro"]["ramp_dph_per_h"] == pytest.approx([20.0] * 3, rel=0.2)
    assert taken["detrend"]["kind"] == "linear"
    assert taken["detrend"]["gyro"]["ramp_dph_per_h"] == pytest.approx([20.0, -20.0, 20.0], rel=0.1)
    assert taken["detrend"]["accel"]["ramp_ug_per_h"] == pytest.approx([0.0] * 3, abs=1.0)
    assert taken["gyro"]["ramp_dph_per_h"] == [None] * 3
    assert taken["unresolved"]["gyro.ramp_dph_per_h.0"].startswith("removed from the record before the analysis")
    assert taken["gyro"]["arw_deg_per_sqrt_h"] == pytest.approx(kept["gyro"]["arw_deg_per_sqrt_h"], rel=0.05)


def test_detrend_temperature_takes_out_what_the_imus_temperature_explains(tmp_path, capsys):
    """A thermal IMU warming by 6 deg C after power-on, its gyro biases 2, -1 and 0.5 deg/h per deg C: without a
    detrend the warm-up reads as a ramp; --detrend temperature gives the coefficients back and leaves none. A
    record without the IMU's temperature is refused in one line."""
    config = _static(tmp_path, duration=2000.0, rate=50.0)
    data = yaml.safe_load(config.read_text())
    data["imu"]["errors"] = {"gyro_noise_dph": [0.5] * 3, "accel_noise_ug": [40.0] * 3,
                             "thermal": {"gyro_bias_dph_per_c": [2.0, -1.0, 0.5], "accel_bias_ug_per_c": [50.0, 0, 0],
                                         "self_heating_c": 6.0, "warmup_tau_s": 300.0}}
    config.write_text(yaml.safe_dump(data))
    docs = {}
    for detrend in ("none", "temperature"):
        assert main(["noise", str(config), "--out", str(tmp_path / detrend), "--no-figures", "--no-history",
                     "--detrend", detrend, "--export", str(tmp_path / "increments.csv")]) == 0
        docs[detrend] = json.loads((tmp_path / detrend / "noise.json").read_text())
    assert docs["none"]["gyro"]["ramp_dph_per_h"][0] > 10.0
    taken = docs["temperature"]["detrend"]
    assert taken["kind"] == "temperature" and taken["degree"] == 2 and 25.0 < taken["about_c"] < 31.0
    assert taken["gyro"]["bias_dph_per_c"] == pytest.approx([2.0, -1.0, 0.5], abs=0.02)
    assert taken["accel"]["bias_ug_per_c"] == pytest.approx([50.0, 0.0, 0.0], abs=0.5)
    assert docs["temperature"]["gyro"]["ramp_dph_per_h"] == [None] * 3
    capsys.readouterr()
    assert main(["noise", str(tmp_path / "increments.csv"), "--out", str(tmp_path / "csv"), "--no-history",
                 "--detrend", "temperature"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "increments.csv" in err and "carries no IMU temperature" in err
