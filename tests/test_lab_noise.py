"""``hil noise LAB.yaml``: the noise terms of devices streaming in their own process (``hil emulate``, a static
table), acquired by the harness started late, recorded and analysed; and the simulation commands refusing a
config that reads devices."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from lab_form import Emulator, emulated, lab_config

from hil.cli import main
from hil.config import ImuErrors
from hil.trial.noise_runner import noise_truth

RATE_HZ = 400.0
ERRORS = {"accel_bias_ug": [60.0, 150.0, 260.0], "accel_noise_ug": [200.0] * 3, "gyro_noise_dph": [20.0] * 3}
pytestmark = pytest.mark.xdist_group("lab")


def test_noise_of_a_lab_config_acquires_the_devices_and_finds_their_white_noise(tmp_path):
    cfg = emulated(RATE_HZ, "kvh1750", duration_s=600.0, kind="static", baudrate=921600)
    cfg["imu"]["errors"] = ERRORS
    with Emulator(tmp_path, cfg) as emulator:
        # a record with a few samples filled (a loaded host's reads late) is still analysed; past 5 % it is refused
        lab = lab_config(cfg, emulator.ports, tmp_path, limits={"missing_max": 0.05})
        out = tmp_path / "noise"
        code = main(["noise", str(lab), "--duration", "40", "--out", str(out), "--no-figures", "--quiet"])
    assert code == 0
    doc = json.loads((out / "noise.json").read_text())
    assert doc["source"] == "devices"
    assert (out / "acquisition" / "recording.mcap").exists() and (out / "acquisition" / "report.html").exists()
    assert doc["samples"] >= 30 * RATE_HZ and not doc["motion_removed"]
    truth = noise_truth(ImuErrors(**ERRORS), RATE_HZ)
    for sensor, key in (("gyro", "arw_deg_per_sqrt_h"), ("accel", "vrw_m_per_s_per_sqrt_h")):
        np.testing.assert_allclose(doc[sensor][key], truth[sensor][key], rtol=0.2, err_msg=sensor)


def test_a_lab_config_whose_devices_are_silent_ends_the_acquisition_early(tmp_path, capsys):
    cfg = emulated(RATE_HZ, "kvh1750", kind="static")
    ports = {"imu": str(tmp_path / "no-imu"), "turntable_data": str(tmp_path / "no-table")}
    lab = lab_config(cfg, ports, tmp_path)
    code = main(["noise", str(lab), "--duration", "5", "--out", str(tmp_path / "n"), "--no-figures", "--quiet"])
    assert code == 2
    assert "no-imu" in capsys.readouterr().err
    assert not (tmp_path / "n" / "noise.json").exists()


@pytest.mark.parametrize("command", ["simulate", "campaign"])
def test_simulation_commands_refuse_a_config_that_reads_devices(tmp_path, capsys, command):
    cfg = emulated(RATE_HZ, "kvh1750", kind="static")
    lab = lab_config(cfg, {"imu": "/dev/ttyUSB0", "turntable_data": "/dev/ttyUSB1"}, tmp_path)
    target = lab
    if command == "campaign":
        target = tmp_path / "campaign.yaml"
        target.write_text(yaml.safe_dump({"base": str(lab), "runs": 2, "seed": 1}))
    code = main([command, str(target), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "imu.source" in err, err
