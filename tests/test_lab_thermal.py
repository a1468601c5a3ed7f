"""The calibration over temperature in the lab form: ``hil emulate`` of configs/calibration_thermal_quick.yaml (made
quick: a fast chamber and sensor, 20, 25 and 30 deg C, six positions of 1 s) in its own process, its emulated
Watlow F4 on a pty, and the harness attached late, setting the chamber over Modbus as it would a real one. The
calibration completes with every thermal coefficient within 4 sigma of the emulator's truth (about 100 s of trial
time, real time: three soaks of 6-10 s and three schedules of 27 s)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from xml.etree import ElementTree

import pytest
import yaml
from lab_form import Emulator, lab_config

from hil.cli import main
from hil.config import parse_config
from hil.outputs.calibration_thermal import thermal_truth

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.xdist_group("lab"),
              pytest.mark.skipif(not os.environ.get("HIL_LAB_TESTS"), reason="lab form: set HIL_LAB_TESTS=1")]


def quick_config() -> dict:
    """configs/calibration_thermal_quick.yaml with seconds-long soaks and schedules."""
    cfg = yaml.safe_load((ROOT / "configs" / "calibration_thermal_quick.yaml").read_text())
    # a KVH 1750 (its counter turns over every 0.64 s at 200 Hz, and pairs on a loaded host where a STIM300's, every
    # 64 ms, may not): its whole-degree temperature reads the sensor's 22, 27 and 32 deg C exactly
    cfg["trial"]["rate_hz"] = cfg["imu"]["rate_hz"] = 200
    cfg["imu"].update(protocol="kvh1750", options={})
    cfg["imu"]["errors"].update(temperature_c=20.0, accel_scale_ppm=[0, 0, 0])
    cfg["imu"]["errors"]["thermal"].update(case_tau_s=1.0, warmup_tau_s=1.0, accel_scale_ppm_per_c=[0, 0, 0])
    cfg["environment"]["chamber"].update(set_point_c=20.0, tau_s=1.0)
    cfg["calibration"] = {"positions": 6, "dwell_s": 1, "settle_s": 0.3, "plateau_s": 0,
                          "accel_terms": ["bias"], "temperatures_c": [20, 25, 30], "thermal_order": 2,
                          "soak": {"stable_within_c": 0.05, "for_s": 2, "timeout_s": 60, "stalled_s": 20}}
    return cfg


def account(out: Path, errors: dict | None = None) -> str:
    """What a failed run did, for the assertion's message: how the trial ended, its verdict and the limits that
    failed it (junit.xml), its streams and residuals (result.json), each temperature's soak, IMU temperature, windows
    and accelerometer biases (calibration.json) and the coefficients' errors in sigmas."""
    lines = []
    if (out / "result.json").exists():
        result = json.loads((out / "result.json").read_text())
        summary = {k: v for k, v in (result.get("calibration") or {}).items() if k != "unobservable"}
        failed = ([f"{f.text}: {f.get('message')}" for f in ElementTree.parse(out / "junit.xml").iter("failure")]
                  if (out / "junit.xml").exists() else [])
        lines += [f"ended: {result['ended']}; verdict: {result.get('verdict')}; failed: {failed}",
                  f"streams: {result.get('streams')}", f"calibration: {summary}"]
    if (out / "calibration.json").exists():
        doc = json.loads((out / "calibration.json").read_text())
        for point in (doc.get("thermal") or {}).get("temperatures", []):
            windows = [(p["samples"], [round(r, 1) for r in p["residual_ug"]]) for p in doc["positions"]
                       if p["temperature_c"] == point["imu_c"]]
            biases = [f"{v:.2f} +- {s:.2f}" for v, s in zip(point["accel"]["bias_ug"],
                                                            point["sigma"]["accel"]["bias_ug"], strict=True)]
            lines.append(f"set point {point['set_point_c']} deg C: chamber {point['chamber_c']}, IMU "
                         f"{point['imu_c']:.3f} deg C after a soak of {point['soak_s']:.1f} s; accel bias {biases} ug; "
                         f"windows (samples, residuals ug) {windows}")
    if errors is not None:
        lines.append(f"error / sigma per coefficient: { {k: [round(e, 2) for e in v] for k, v in errors.items()} }")
    return "\n".join(lines) or f"no result.json in {out}"


def test_a_calibration_over_three_temperatures_of_a_running_emulator_finds_its_thermal_terms_within_4_sigma(
        tmp_path):
    cfg = quick_config()
    with Emulator(tmp_path, cfg, duration=400.0) as emulator:
        lab = lab_config(cfg, emulator.ports, tmp_path, commanded=True)
        doc = yaml.safe_load(lab.read_text())
        doc["environment"]["chamber"] = {"controller": "watlow-f4", "port": emulator.ports["chamber"]}
        lab.write_text(yaml.safe_dump(doc))
        time.sleep(1.0)
        out = tmp_path / "cal"
        code = main(["calibrate", str(lab), "--out", str(out), "--viewer", "none", "--quiet", "--no-figures"])
        emulator.stop()
    written = json.loads((out / "calibration.json").read_text()) if (out / "calibration.json").exists() else {}
    assert "thermal" in written, f"hil calibrate exited {code}\n{account(out)}"
    thermal = written["thermal"]
    emulated = parse_config(cfg)  # the lab config knows no truth: the emulator's
    _, truth = thermal_truth(emulated.imu.errors, emulated.turntable.zero_offset_arcsec, thermal["reference_c"], 2)
    errors = {name: [(c - t) / s for c, s, t in zip(term["coefficients"], term["sigma"], truth["terms"][name],
                                                     strict=True)] for name, term in thermal["terms"].items()}
    assert code == 0, f"hil calibrate exited {code}\n{account(out, errors)}"
    assert [t["set_point_c"] for t in thermal["temperatures"]] == [20, 25, 30]
    assert set(errors) == {"accel.bias_ug.0", "accel.bias_ug.1", "accel.bias_ug.2"}
    assert all(abs(e) <= 4.0 for values in errors.values() for e in values), account(out, errors)
