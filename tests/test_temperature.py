"""The IMU's own temperature: decoded from every protocol whose frames carry one (golden frames from the devices'
documents), carried on the samples, kept by the recording (a replay reads the same), in series.csv's
``temperature_c`` and result.json's ``streams.imu_temperature_c``; an emulated IMU reports a constant."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest
import yaml
from test_health_flags import KVH_POWER_UP
from test_stim300 import TEMPERATURE_A5

from drivers.can_dbc import CanDbcCodec
from drivers.codec import RawChunk
from drivers.kvh1750 import Kvh1750Codec
from drivers.stim300 import Stim300Codec
from drivers.xsens import XsensCodec
from hil.cli import main
from hil.samples import ImuSample

ROOT = Path(__file__).resolve().parents[1]

# MTData2 by the Xsens MT Low-Level Communication Protocol: PacketCounter 9, Temperature (0x0810, Float32)
# 41.25 deg C = 0x42250000, DeltaQ (1, 0, 0, 0), DeltaV (0, 0, 0.0098154) m/s; checksum 0xF3.
XSENS_TEMPERATURE = bytes.fromhex("FAFF362E 1020020009 08100442250000 8030103F800000000000000000000000000000"
                                  "40100C00000000000000003C20D0E5 F3")
# A lab CAN IMU's DBC with a temperature message beside the shipped DBC's increments (1/100 deg C per bit).
TEMPERATURE_DBC = '''
BO_ 262 IMU_Temp: 8 IMU
 SG_ Temp : 0|16@1- (0.01,0) [-327.68|327.67] "degC" HOST
 SG_ SyncCounter : 32|24@1+ (1,0) [0|16777215] "" HOST
 SG_ Status : 56|8@1+ (1,0) [0|255] "" HOST
'''


def _temperatures(codec, data: bytes) -> list[float]:
    return codec.samples(codec.framer(None).feed_chunk(RawChunk("imu", 0.0, data))).temperature_c.tolist()


def test_each_protocol_decodes_the_temperature_its_frames_carry():
    assert _temperatures(Kvh1750Codec(1000), KVH_POWER_UP) == [29.0]
    stim = Stim300Codec(2000, datagram=0xA5, gyro_output="rate", accel_output="acceleration", accel_range_g=10)
    assert _temperatures(stim, TEMPERATURE_A5) == [pytest.approx((25.5 - 1.0 + 0.0 + 3 * 25.0) / 6, abs=1e-12)]
    xsens = XsensCodec(100)
    assert xsens.decode(XSENS_TEMPERATURE).temperature == 41.25
    assert _temperatures(xsens, XSENS_TEMPERATURE) == [41.25]


def test_a_kvh_set_to_fahrenheit_is_read_in_celsius_and_its_csv_column_says_which():
    fahrenheit = Kvh1750Codec(1000, temperature_unit="F")
    assert _temperatures(fahrenheit, KVH_POWER_UP) == [pytest.approx((29 - 32) * 5 / 9, abs=1e-12)]
    assert fahrenheit.decode(fahrenheit.encode(fahrenheit.from_sample(
        ImuSample(3, (0.0,) * 3, (0.0, 0.0, 0.01), temperature_c=40.0)))).temperature == 104
    assert fahrenheit.csv_header()[-1] == "temperature_f" and Kvh1750Codec(1000).csv_header()[-1] == "temperature_c"


def test_frames_without_a_temperature_give_nan():
    stim = Stim300Codec(500, datagram=0x91)
    frame = stim.encode(stim.from_sample(ImuSample(4, (0.0,) * 3, (0.0, 0.0, 0.02), temperature_c=30.0)))
    xsens = XsensCodec(100)  # an MTi not set to send its Temperature
    message = xsens.encode(xsens.from_sample(ImuSample(4, (0.0,) * 3, (0.0, 0.0, 0.02), temperature_c=30.0)))
    assert all(math.isnan(t) for t in _temperatures(stim, frame) + _temperatures(xsens, message))


def test_a_can_imu_reads_its_temperature_signal(tmp_path):
    dbc = tmp_path / "lab.dbc"
    head, tail = (ROOT / "configs" / "imu_lab_highres.dbc").read_text().split("BU_: IMU HOST\n", 1)
    dbc.write_text(head + "BU_: IMU HOST\n" + TEMPERATURE_DBC + tail)
    codec = CanDbcCodec(dbc, 200.0, ("IMU_DThetaX.DThetaX", "IMU_DThetaY.DThetaY", "IMU_DThetaZ.DThetaZ"),
                        ("IMU_DVX.DVX", "IMU_DVY.DVY", "IMU_DVZ.DVZ"), "SyncCounter", "Status", "IMU_Temp.Temp")
    messages = codec.encode(codec.from_sample(ImuSample(11, (1e-6, 0.0, 0.0), (0.0, 0.0, 0.049), temperature_c=37.25)))
    assert [m.arbitration_id for m in messages] == [256, 257, 258, 259, 260, 261, 262]
    framer = codec.framer(None)
    batches = [framer.feed_chunk(RawChunk("imu", 0.0, bytes(m.data), m.arbitration_id)) for m in messages]
    assert codec.samples(batches[-1]).temperature_c.tolist() == [37.25]
    assert codec.csv_header()[-1] == "temperature_c" and codec.record(batches[-1].rows[0]).temperature == 37.25


def _emulated(tmp_path, protocol: str, imu: dict) -> Path:
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["imu"].update(protocol=protocol, **imu)
    cfg["imu"]["errors"]["temperature_c"] = 31.25
    cfg["trial"]["duration_s"] = 5.0
    cfg["output"] = {"limits": {}}
    path = tmp_path / f"{protocol}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _outputs(out: Path) -> tuple[dict | None, list[str]]:
    streams = json.loads((out / "result.json").read_text())["streams"]
    return streams.get("imu_temperature_c"), [row["temperature_c"] for row in csv.DictReader((out / "series.csv").open())]


@pytest.mark.parametrize(("protocol", "imu", "reported"), [
    ("kvh1750", {}, 31.0),  # whole deg C
    ("xsens-mtdata2", {"options": {"temperature": True}}, 31.25),
    ("stim300", {"rate_hz": 1000, "options": {"datagram": 0xA5}}, 31.25),  # 1/256 deg C
])
def test_an_emulated_imus_temperature_reaches_series_csv_and_result_json_and_a_replay(tmp_path, protocol, imu, reported):
    out = tmp_path / "run"
    args = ["--viewer", "none", "--no-figures", "--quiet"]
    assert main(["run", str(_emulated(tmp_path, protocol, imu)), "--speed", "max", "--out", str(out), *args]) == 0
    summary, column = _outputs(out)
    assert summary == {"mean": reported, "min": reported, "max": reported}
    assert len(column) == 5 and {float(t) for t in column} == {reported}
    if protocol == "kvh1750":
        assert main(["replay", str(out), "--out", str(tmp_path / "again"), *args[:3]]) == 0
        assert _outputs(tmp_path / "again") == (summary, column)


def test_a_simulation_has_no_temperature(tmp_path):
    out = tmp_path / "sim"
    assert main(["simulate", str(_emulated(tmp_path, "kvh1750", {})), "--out", str(out), "--viewer", "none",
                 "--no-figures"]) == 0
    summary, column = _outputs(out)
    assert summary is None and column and set(column) == {""}
