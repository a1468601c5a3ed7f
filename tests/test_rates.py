"""``hil run`` with the IMU faster than the table: one pulse train at the IMU rate, the table latching
every n-th pulse of it at 200 Hz."""

import json

import numpy as np
import pytest
import yaml

from hil.cli import main

TABLE_RATE = 200


@pytest.mark.slow
@pytest.mark.parametrize("imu_rate, duration", [(1000, 30.0), (2000, 24.0)])  # about 30 s each on 2 cores
def test_an_imu_faster_than_the_table_is_aligned_and_estimated(tmp_path, imu_rate, duration):
    data = yaml.safe_load(open("configs/emulated_swing.yaml"))
    data["imu"]["rate_hz"] = imu_rate  # the table keeps trial.rate_hz and the default 115200 baud
    config = tmp_path / "fast_imu.yaml"
    config.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    code = main(["run", str(config), "--duration", str(duration), "--speed", "max", "--quiet", "--viewer", "none",
                 "--no-figures", "--out", str(out)])
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    samples = round(duration * imu_rate)
    streams = result["streams"]
    assert result["trial"]["samples"] == streams["imu_frames"] == streams["aligned"] == samples
    assert streams["table_frames"] == round(duration * TABLE_RATE) and streams["dropped"] == 0
    assert streams["imu_gated"] == streams["imu_implausible"] == 0
    assert abs(streams["sync_offset_ms"]) < 0.01
    assert json.loads((out / "emulator.json").read_text())["pulses"] == samples
    est = result["estimate"]
    assert est["observable"] and est["gram_rank"] == 12
    error = np.subtract(est["accel_bias_ug"], result["truth"]["accel_bias_ug"])
    assert np.all(np.abs(error) < 5 * np.array(est["accel_bias_sigma_ug"]))
