"""The harness attached to devices that are already streaming (the lab form): ``hil emulate`` in its own process
from the start, its counters at their own values, and ``hil run`` pointed at its ports seconds later, after
several wraps of the IMU's counter. Each completes with little unpaired, nothing rejected by the gyro/table
gate, and the bias within 5 sigma of the emulator's truth."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from lab_form import Emulator, emulated, lab_config, result, within_sigmas

from drivers.acl import parse_message
from hil.cli import main
from hil.config import parse_config
from hil.outputs.calibration_report import comparison, observed_truth
from hil.pytest_plugin import read_cases
from tests.helpers import processed

TRIAL_S = 10.0
# real-time trials of devices in their own processes, at up to 2 kHz: their receive times are the host's, so they
# are run on a host that is not also running the rest of the suite (HIL_LAB_TESTS=1 python -m pytest
# tests/test_lab_attach.py), one at a time; the suite's own emulated trials count from seeded starts too
pytestmark = [pytest.mark.xdist_group("lab"),
              pytest.mark.skipif(not os.environ.get("HIL_LAB_TESTS"), reason="lab form: set HIL_LAB_TESTS=1")]


def _attach(tmp_path, cfg: dict, late_s: float, duration: float = TRIAL_S) -> dict:
    with Emulator(tmp_path, cfg) as emulator:
        lab = lab_config(cfg, emulator.ports, tmp_path)
        time.sleep(max(0.0, late_s - (time.monotonic() - emulator.started)))
        out = tmp_path / "run"
        code = main(["run", str(lab), "--duration", str(duration), "--out", str(out), "--viewer", "none", "--quiet",
                     "--no-figures"])
    assert code == 0, {k: v for k, v in result(out)["streams"].items() if v}
    return result(out)


def _judged(doc: dict, rate_hz: float) -> None:
    streams = doc["streams"]
    sync = streams["sync"]
    assert doc["ended"] == "completed"
    assert sync["paired_by"] == "motion" and sync["repairs"] == []
    assert sync["unpaired"] <= rate_hz  # no more than 1 s of samples
    assert streams["imu_gated"] == 0
    assert within_sigmas(doc), doc["estimate"]


@pytest.mark.parametrize(("protocol", "rate_hz", "start", "late_s"), [
    ("kvh1750", 200.0, 5, 2.5),  # 7-bit counter: 0.64 s a wrap at 200 Hz, 64 ms at 2 kHz
    ("kvh1750", 1000.0, 100, 1.5),
    ("kvh1750", 2000.0, 17, 1.5),
    ("xsens-mtdata2", 200.0, 65_536 - 100, 2.0),  # attached past the 16-bit wrap
    ("xsens-mtdata2", 1000.0, 65_536 - 500, 2.0),
    ("can-dbc", 200.0, None, 2.0),
])
def test_attached_late_after_counter_wraps_the_trial_pairs_and_completes(tmp_path, protocol, rate_hz, start, late_s,
                                                                         request):
    if protocol == "can-dbc":
        request.getfixturevalue("udp_multicast_alone")
    timing = {"counter_start": start} if start is not None else {}
    cfg = emulated(rate_hz, protocol, baudrate=921600, timing=timing)
    cfg["turntable"]["timing"] = {"counter_start": 777_777}
    _judged(_attach(tmp_path, cfg, late_s), rate_hz)


def test_a_static_table_is_paired_by_receive_time_and_says_so(tmp_path):
    cfg = emulated(200.0, kind="static", timing={"counter_start": 3})
    doc = _attach(tmp_path, cfg, 2.0, duration=6.0)
    sync = doc["streams"]["sync"]
    assert doc["ended"] == "completed" and sync["paired_by"] == "receive_time"
    assert sync["confirmed_at_s"] is None and sync["accuracy_ms"] > 0  # the host's jitter: larger on a loaded one
    streams = doc["streams"]
    assert streams["imu_frames"] == streams["aligned"] + streams["aligner_after_table_end"]
    assert streams["aligner_without_angles"] == 0


@pytest.mark.parametrize("device", ["imu", "turntable"])
def test_a_power_cycle_mid_trial_is_noticed_re_paired_and_the_trial_goes_on(tmp_path, device):
    """The device is silent for 1 s, then counts from zero: the pairing breaks on the receive times, the
    stream is paired anew, and the trial completes with the re-pairing counted and the bias kept."""
    cfg = emulated(200.0, timing={"counter_start": 40})
    cfg[device]["faults"] = {"power_cycle_at_s": 6.0, "power_cycle_s": 1.0}
    with Emulator(tmp_path, cfg) as emulator:
        lab = lab_config(cfg, emulator.ports, tmp_path, limits={"missing_max": 0.2, "without_angles_max": 0.2,
                                                                "gated_max": 0.02})
        time.sleep(max(0.0, 1.5 - (time.monotonic() - emulator.started)))
        out = tmp_path / "run"
        code = main(["run", str(lab), "--duration", "14", "--out", str(out), "--viewer", "none", "--quiet",
                     "--no-figures"])
    doc = result(out)
    sync = doc["streams"]["sync"]
    assert code == 0 and doc["ended"] == "completed", (doc["ended"], {k: v for k, v in doc["streams"].items() if v})
    # the stream is re-paired by its motion against the other's; the IMU's motion check may then move it by a pulse
    assert 1 <= len(sync["repairs"]) <= 2 and sync["repairs"][0]["cause"].startswith({"imu": "imu", "turntable": "table"}[device])
    assert 3.0 < sync["repairs"][0]["at_s"] < 8.0  # the power cycle, 1.5 s after the harness started
    # no sample meets the angles of another pulse: a table's samples wait for the motion to place them
    assert doc["streams"]["imu_gated"] <= 0.02 * doc["streams"]["aligned"] and within_sigmas(doc)
    again = tmp_path / "again"
    assert main(["replay", str(out), "--out", str(again), "--no-figures", "--viewer", "none"]) == 0
    assert processed(again) == processed(out)  # a replay has its own record, the rest bit for bit


def test_a_harness_stopped_for_a_second_and_a_half_notices_the_lost_wraps_and_completes(tmp_path):
    """A 2 kHz KVH wraps its counter every 64 ms: while the harness is stopped (SIGSTOP) for 1.5 s its IMU port
    overflows (a pty holds about 64 KiB, 0.9 s of the KVH's 72 kB/s) and frames are lost; whatever the
    unwrapped counter then says, the stream is paired again."""
    import signal
    import subprocess
    import sys

    cfg = emulated(2000.0, baudrate=921600, timing={"counter_start": 17})
    with Emulator(tmp_path, cfg) as emulator:
        lab = lab_config(cfg, emulator.ports, tmp_path, limits={"missing_max": 0.2, "gated_max": 0.02,
                                                                "without_angles_max": 0.05})
        out = tmp_path / "run"
        harness = subprocess.Popen([sys.executable, "-m", "hil.cli", "run", str(lab), "--duration", "12", "--out",
                                    str(out), "--viewer", "none", "--quiet", "--no-figures"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        time.sleep(5.0)
        harness.send_signal(signal.SIGSTOP)
        time.sleep(1.5)
        harness.send_signal(signal.SIGCONT)
        code = harness.wait(60)
    doc = result(out)
    failed = [case for case in read_cases(out / "junit.xml") if case.outcome != "passed"] if code == 3 else []
    assert code == 0, (harness.stderr.read().decode(), failed, {k: v for k, v in doc["streams"].items() if v})
    streams = doc["streams"]
    assert doc["ended"] == "completed"
    assert streams["imu_missing"] + streams["sync"]["unpaired"] > 0  # the stall lost frames
    # while the receive times are refined to the pulse the gate may take a few samples
    assert streams["imu_gated"] <= 0.02 * streams["aligned"] and within_sigmas(doc)


def test_a_trial_that_commands_the_table_of_a_running_emulator_completes_and_leaves_it_off(tmp_path):
    cfg = emulated(200.0)
    with Emulator(tmp_path, cfg) as emulator:
        lab = lab_config(cfg, emulator.ports, tmp_path, commanded=True)
        time.sleep(1.0)
        out = tmp_path / "run"
        assert main(["run", str(lab), "--duration", "10", "--out", str(out), "--viewer", "none", "--quiet",
                     "--no-figures"]) == 0
        emulator.stop()
        stats = json.loads(emulator.stats_file.read_text())
    doc = result(out)
    assert doc["ended"] == "completed" and doc["streams"]["sync"]["paired_by"] == "motion" and within_sigmas(doc)
    assert stats["table_modes_off"] >= 1 and stats["table_modes"] == "Off,Off,Off"


def _calibrated(tmp_path: Path, config: str, duration: float, **change: dict) -> tuple[int, Path, Path, dict]:
    """``hil calibrate`` on a running ``hil emulate`` of ``configs/CONFIG`` (its blocks updated by ``change``):
    the exit code, the output directory, the lab config and the emulator's statistics."""
    import yaml

    cfg = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs" / config).read_text())
    for block, values in change.items():
        cfg[block].update(values)
    with Emulator(tmp_path, cfg, duration=duration) as emulator:
        lab = lab_config(cfg, emulator.ports, tmp_path, commanded=True)
        time.sleep(1.0)
        out = tmp_path / "cal"
        code = main(["calibrate", str(lab), "--out", str(out), "--viewer", "none", "--quiet", "--no-figures"])
        emulator.stop()
        stats = json.loads(emulator.stats_file.read_text())
    return code, out, lab, {**stats, "config": cfg}


def test_a_calibration_of_a_running_emulator_completes(tmp_path):
    code, out, _, stats = _calibrated(tmp_path, "calibration_short.yaml", 300.0)
    assert code == 0
    cfg = stats["config"]
    doc = json.loads((out / "calibration.json").read_text())
    assert len(doc["positions"]) == 18 and result(out)["streams"]["sync"]["repairs"] == []
    emulator_cfg = parse_config(cfg)  # the lab config knows no truth: the emulator's
    doc["truth"] = {"as_observed": observed_truth(emulator_cfg.imu.errors, emulator_cfg.turntable.zero_offset_arcsec)}
    judged = [(r["term"], r["error_sigma"]) for r in comparison(doc) if r["error_sigma"] is not None]
    assert len(judged) >= 28 and all(abs(e) <= 3.0 for _, e in judged), judged
    # every message the harness sent is in the Acutrol language, and none was refused
    assert stats["table_log"] and all(code == 0 and parse_message(line) for line, code in stats["table_log"])
    assert stats["table_modes"] == "Off,Off,Off"


def test_a_gyro_rate_test_on_a_running_emulated_rate_table_completes_within_3_sigma(tmp_path):
    code, out, _, stats = _calibrated(tmp_path, "calibration_rate_table.yaml", 200.0)
    assert code == 0
    cfg = stats["config"]
    doc = json.loads((out / "calibration.json").read_text())
    emulator_cfg = parse_config(cfg)  # the lab config knows no truth: the emulator's
    doc["truth"] = {"as_observed": observed_truth(emulator_cfg.imu.errors, emulator_cfg.turntable.zero_offset_arcsec)}
    judged = [(r["term"], r["error_sigma"]) for r in comparison(doc) if r["error_sigma"] is not None]
    assert {"gyro.bias_dph.2", "gyro.scale_ppm.2"} <= {t for t, _ in judged}
    assert all(abs(e) <= 3.0 for _, e in judged), judged
    assert [line for line, _ in stats["table_log"]][:2] == ["VEL60", "ACL120"]
    assert {"JOG30.000000", "JOG-30.000000", "STO"} <= {line for line, _ in stats["table_log"]}
    assert stats["table_modes"] == "Off" and all(code == 0 for _, code in stats["table_log"])


@pytest.mark.parametrize("faults", [
    {"drop_rate": 0.003, "drop_burst": 4},  # 1.2 % of the frames lost, a few in every window
    {"power_cycle_at_s": 20.0, "power_cycle_s": 15.0},  # 15 s silent once attached: windows lost, or samples bridged
])
def test_a_calibration_whose_imu_loses_samples_is_not_filed_as_pass(tmp_path, faults):
    """Ended early naming the window that lacks samples, or completed and FAILed on the samples missing."""
    from hil.config import load_config
    from hil.outputs.measurements import FAIL, measurements

    code, out, lab, _ = _calibrated(tmp_path, "calibration_short.yaml", 300.0,
                                    calibration={"positions": 6, "plateau_s": 3}, imu={"faults": faults})
    doc = result(out)
    failed = {m.name for m in measurements(doc, load_config(lab).limits) if m.outcome == FAIL}
    if code == 1:
        assert "rejected or lost" in doc["ended"] and not (out / "calibration.json").exists(), doc["ended"]
    else:
        assert code == 3 and doc["ended"] == "completed" and "imu_missing_fraction" in failed, (code, failed)
