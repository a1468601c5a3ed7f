"""``hil run`` end to end with an emulated STIM300 and an Xsens set to FP16.32: the bias found within 5 sigma,
every frame read, and the replay of the recording bit-identical."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil.cli import main
from tests.helpers import processed

ROOT = Path(__file__).resolve().parents[1]
DURATION = 120


@pytest.mark.parametrize(("name", "imu", "rate"), [
    ("stim300", {"protocol": "stim300", "options": {"datagram": 0x93, "gyro_output": "increment"}}, 250.0),
    ("xsens-fp16.32", {"protocol": "xsens-mtdata2", "options": {"precision": "fp16.32"}}, 200.0),
])
def test_an_emulated_device_runs_end_to_end_and_replays_bit_identically(tmp_path, name, imu, rate):
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["trial"]["rate_hz"] = rate
    cfg["imu"].update(imu)
    cfg["output"]["limits"] = {}
    path, out, again = tmp_path / f"{name}.yaml", tmp_path / "run", tmp_path / "replay"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--duration", str(DURATION), "--speed", "max", "--quiet", "--no-figures",
                 "--viewer", "none", "--out", str(out)]) == 0
    result = json.loads((out / "result.json").read_text())
    streams = result["streams"]
    assert streams["imu_frames"] == streams["aligned"] == DURATION * rate
    assert streams["dropped"] == streams["corrupt"] == 0
    est = result["estimate"]
    error = np.subtract(est["accel_bias_ug"], result["truth"]["accel_bias_ug"])
    assert np.all(np.abs(error) < 5 * np.array(est["accel_bias_sigma_ug"]))
    assert main(["replay", str(out), "--out", str(again), "--no-figures", "--viewer", "none"]) == 0
    assert processed(again) == processed(out)
    assert (again / "series.csv").read_text() == (out / "series.csv").read_text()
