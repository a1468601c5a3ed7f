"""Codecs as plug-ins: ``imu.protocol`` a registry name, ``imu.options`` validated by the codec's own model, the
old ``imu.kvh1750`` block taken with one deprecation line, codecs found by name for the table too."""

from __future__ import annotations

import logging

import pytest

from drivers.codec import Codec
from drivers.registry import CODECS, imu_codec, make_codec
from hil.config import ConfigError, parse_config

BASE = {"trial": {"duration_s": 10}, "site": {"latitude_deg": 32}}


def config(imu: dict):
    return parse_config({**BASE, "imu": imu})


def test_imu_protocol_is_a_registry_name_and_its_options_the_codecs():
    cfg = config({"protocol": "xsens-mtdata2", "options": {"precision": "fp16.32"}})
    codec = imu_codec(cfg.imu, 200.0)
    assert (codec.precision, codec.outputs) == ("fp16.32", "increments")  # the default filled in
    with pytest.raises(ConfigError, match=r"imu.protocol: 'nmea': unknown; IMU protocols: can-dbc, kvh1750, stim300, "):
        config({"protocol": "nmea"})
    with pytest.raises(ConfigError, match=r"imu.protocol: 'tts1': unknown; IMU protocols: can-dbc, kvh1750, "):
        config({"protocol": "tts1"})
    with pytest.raises(ConfigError, match=r"imu.options: precision: Input should be .* \(the xsens-mtdata2 options\)"):
        config({"protocol": "xsens-mtdata2", "options": {"precision": "float16"}})
    with pytest.raises(ConfigError, match=r"imu.options: gyro_unit: unknown key \(the can-dbc options\)"):
        config({"protocol": "can-dbc", "options": {"gyro_unit": "deg"}})


def test_the_old_kvh1750_block_is_taken_as_options_with_one_deprecation_line(caplog):
    with caplog.at_level(logging.WARNING):
        cfg = config({"kvh1750": {"gyro_unit": "deg", "accel_unit": "m/s^2"}})
    assert cfg.imu.options == {"gyro_unit": "deg", "gyro_output": "delta", "accel_unit": "m/s^2", "temperature_unit": "C",
                               "check_config": True}
    assert [r.getMessage() for r in caplog.records] == [
        "hil: imu.kvh1750 is deprecated and will be removed: write its keys under imu.options"]
    with pytest.raises(ConfigError, match="imu: kvh1750: give the KVH 1750's settings in imu.options only"):
        config({"kvh1750": {}, "options": {}})


def test_every_codec_is_found_by_name_and_built_with_its_options():
    for name in CODECS.names():
        assert CODECS.get(name).name == name
    table = make_codec("tts1", pulses_per_frame=5)
    assert table.kind == "table" and table.sequence_step == 5
    with pytest.raises(ValueError, match="pulses_per_frame"):
        make_codec("tts1", pulses_per_frame=0)


def test_the_codec_interface_is_declared_on_the_base_with_its_defaults():
    kvh, xsens, can_dbc = (imu_codec(config({"protocol": p}).imu, 200.0) for p in ("kvh1750", "xsens-mtdata2",
                                                                                 "can-dbc"))
    xsens_bytes = 4 + 5 + 7 + 7 + 19 + 15 + 1  # header, counter, sample time, status, DeltaQ, DeltaV, checksum
    assert (kvh.frame_bytes(), xsens.frame_bytes(), can_dbc.frame_bytes()) == (36, xsens_bytes, 0)
    assert (kvh.counter_modulus, xsens.counter_modulus, can_dbc.counter_modulus) == (128, 65536, 1 << 24)
    assert kvh.unit_advice()[0] == "imu.options.accel_unit"
    assert xsens.unit_advice() == ("imu.protocol (xsens-mtdata2)",) * 3
    assert (kvh.healthy_status, xsens.healthy_status, xsens.device_time, kvh.device_time) == (0x77, 1, True, False)
    abstract = {name for name, value in vars(Codec).items() if getattr(value, "__isabstractmethod__", False)}
    assert abstract == {"encode", "framer", "record", "samples", "from_sample", "csv_header", "csv_row"}
