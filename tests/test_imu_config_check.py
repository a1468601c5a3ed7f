"""The IMU's own configuration asked for as a trial attaches: the KVH 1750's configuration mode and the MTi's
ReqOutputConfiguration, read from golden replies typed from the documents; a device set otherwise than the config
is exit 2 before anything is acquired, naming the key and the device's answer; a silent device is one warning and
an unchecked trial; a reply the codec cannot read is exit 2 naming it. The emulated devices answer as the devices
do (in process by default; the lab form, ``hil emulate`` in its own process, with HIL_LAB_TESTS=1)."""

from __future__ import annotations

import json
import os
import time

import pytest
import yaml
from lab_form import Emulator, emulated, lab_config

from drivers.codec import RawChunk
from drivers.config_query import Exchange, NoAnswer
from drivers.kvh1750 import HEADER, Kvh1750Codec, reply_line
from drivers.transport import SerialTransport
from drivers.xbus import xbus_message, xbus_messages
from drivers.xsens import XsensCodec
from emulators.imu_commands import CommandedPty, KvhResponder, XsensResponder
from emulators.in_process import EmulatorThread
from hil.cli import main
from hil.config import parse_config
from hil.samples import ImuSample
from hil.trial.imu_config import ConfigMismatch, check_imu_config

# Xbus messages typed from the MT Low Level Communication Protocol: FA, BID FF, MID, LEN, data, and a checksum that
# makes every byte after the preamble sum to 0 mod 256
GO_TO_CONFIG = bytes.fromhex("FA FF 30 00 D1")
GO_TO_CONFIG_ACK = bytes.fromhex("FA FF 31 00 D0")
REQ_OUTPUT_CONFIGURATION = bytes.fromhex("FA FF C0 00 41")
GO_TO_MEASUREMENT = bytes.fromhex("FA FF 10 00 F1")
GO_TO_MEASUREMENT_ACK = bytes.fromhex("FA FF 11 00 F0")
ERROR_INVALID_MESSAGE = bytes.fromhex("FA FF 42 01 04 BA")
# OutputConfiguration (0xC1): PacketCounter, SampleTimeFine, StatusWord with every message (0xFFFF), DeltaQ and
# DeltaV (Float32) at 200 Hz
OUTPUTS_200HZ = bytes.fromhex("FA FF C1 14 10 20 FF FF 10 60 FF FF E0 20 FF FF 80 30 00 C8 40 10 00 C8 02")
# the same without DeltaV: RateOfTurn (0x8020) in its place
OUTPUTS_NO_DELTA_V = bytes.fromhex("FA FF C1 14 10 20 FF FF 10 60 FF FF E0 20 FF FF 80 30 00 C8 80 20 00 C8 B2")


class ScriptedPort:
    """A byte port whose device answers each request from ``script`` ({request bytes: reply bytes}), the
    replies amid ``noise`` (streaming frames); a request not in the script is not answered."""

    byte_stream = True
    address = "scripted://imu"

    def __init__(self, script: dict[bytes, bytes], noise: bytes = b"") -> None:
        self.script, self.noise = script, noise
        self.incoming = bytearray(noise)
        self.written: list[bytes] = []
        self.opened = self.closed = 0

    def open(self) -> None:
        self.opened += 1

    def close(self) -> None:
        self.closed += 1

    def write(self, data: bytes) -> None:
        self.written.append(data)
        self.incoming += self.noise + self.script.get(data, b"") + self.noise

    def read(self) -> list[RawChunk]:
        data, self.incoming = bytes(self.incoming), bytearray()
        return [RawChunk("imu", 0.0, data)] if data else []


def kvh_script(**answers: str) -> dict[bytes, bytes]:
    """A KVH 1750's replies to the configuration queries, as the manual writes them ("NAME,VALUE" CR LF)."""
    values = {"MSYNC": "IMU", "DR": "200", "ROTFMT": "DELTA", "ROTUNITS": "RAD", "TEMPUNITS": "C", **answers}
    return {b"=CONFIG,1\r\n": b"CONFIG,1\r\n",
            **{f"?{name}\r\n".encode(): f"{name},{value}\r\n".encode() for name, value in values.items()}}


KVH_FRAME = Kvh1750Codec(200.0).encode(Kvh1750Codec(200.0).from_sample(ImuSample(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))))


def _check(codec, port, warnings=None):
    return check_imu_config(codec, port, (warnings if warnings is not None else []).append)


def test_the_xsens_messages_are_the_documents_bytes():
    for message in (GO_TO_CONFIG, GO_TO_CONFIG_ACK, REQ_OUTPUT_CONFIGURATION, GO_TO_MEASUREMENT,
                    GO_TO_MEASUREMENT_ACK, ERROR_INVALID_MESSAGE, OUTPUTS_200HZ, OUTPUTS_NO_DELTA_V):
        assert sum(message[1:]) % 256 == 0  # the rule, checked on the typed bytes
    assert xbus_message(0x30) == GO_TO_CONFIG and xbus_message(0xC0) == REQ_OUTPUT_CONFIGURATION
    assert xbus_message(0x10) == GO_TO_MEASUREMENT and xbus_message(0x42, b"\x04") == ERROR_INVALID_MESSAGE
    stream = b"\x00\xfa\xff" + GO_TO_CONFIG_ACK + OUTPUTS_200HZ[:9]  # noise, a message, one still arriving
    assert xbus_messages(stream) == ([(0x31, b"")], 3 + len(GO_TO_CONFIG_ACK))


def test_a_kvh_answering_1000_hz_to_a_200_hz_config_is_refused_naming_imu_rate_hz():
    port = ScriptedPort(kvh_script(DR="1000"), noise=KVH_FRAME)
    with pytest.raises(ConfigMismatch) as refused:
        _check(Kvh1750Codec(200.0), port)
    assert str(refused.value).startswith("imu.rate_hz: the IMU says 'DR,1000' (1000 Hz), the config 200 Hz")
    assert port.written[-1] == b"=CONFIG,0\r\n" and port.closed == 1  # left streaming, its port released


def test_a_kvh_sending_rates_to_a_delta_config_is_refused_naming_imu_options_gyro_output():
    with pytest.raises(ConfigMismatch, match=r"^imu\.options\.gyro_output: the IMU says 'ROTFMT,RATE' \(rate\), "
                                             r"the config delta"):
        _check(Kvh1750Codec(200.0), ScriptedPort(kvh_script(ROTFMT="RATE")))


def test_a_kvh_set_as_configured_is_recorded_with_its_replies():
    record = _check(Kvh1750Codec(200.0, gyro_unit="deg"), ScriptedPort(kvh_script(ROTUNITS="DEG"), KVH_FRAME))
    assert record["answered"] and record["replies"]["DR"] == "DR,200"
    assert record["settings"] == {"imu.rate_hz": 200.0, "imu.options.gyro_output": "delta",
                                  "imu.options.gyro_unit": "deg", "imu.options.temperature_unit": "C"}


def test_an_externally_synced_kvh_is_not_judged_on_its_internal_data_rate():
    record = _check(Kvh1750Codec(200.0), ScriptedPort(kvh_script(MSYNC="EXT", DR="1000")))
    assert "imu.rate_hz" not in record["settings"] and record["replies"]["DR"] == "DR,1000"


def test_a_reply_the_codec_cannot_read_is_refused_naming_it():
    script = {**kvh_script(), b"?ROTUNITS\r\n": b"INVALID,?ROTUNITS\r\n"}
    with pytest.raises(ConfigMismatch, match=r"answers '\?ROTUNITS' with 'INVALID,\?ROTUNITS'"):
        _check(Kvh1750Codec(200.0), ScriptedPort(script))
    script = {GO_TO_CONFIG: GO_TO_CONFIG_ACK, REQ_OUTPUT_CONFIGURATION: ERROR_INVALID_MESSAGE}
    with pytest.raises(ConfigMismatch, match="answers ReqOutputConfiguration .0xC0. with Error FA FF 42 01 04 BA"):
        _check(XsensCodec(200.0), ScriptedPort(script))


def test_a_silent_device_is_one_warning_and_the_trial_goes_on_unchecked():
    warnings: list[str] = []
    port = ScriptedPort({}, noise=KVH_FRAME)
    record = _check(Kvh1750Codec(200.0), port, warnings)
    assert record == {"answered": False, "replies": {}, "settings": {}}
    assert len(warnings) == 1 and "no answer to '=CONFIG,1' within 1 s on scripted://imu" in warnings[0]
    assert port.written[-1] == b"=CONFIG,0\r\n" and port.closed == 1


def test_the_check_is_skipped_when_switched_off():
    port = ScriptedPort({})
    assert _check(Kvh1750Codec(200.0, check_config=False), port) is None and port.opened == 0


XSENS_SCRIPT = {GO_TO_CONFIG: GO_TO_CONFIG_ACK, GO_TO_MEASUREMENT: GO_TO_MEASUREMENT_ACK}


def test_an_mti_is_read_from_its_output_configuration():
    record = _check(XsensCodec(200.0), ScriptedPort({**XSENS_SCRIPT, REQ_OUTPUT_CONFIGURATION: OUTPUTS_200HZ}))
    assert record["settings"] == {"imu.rate_hz": 200.0, "imu.options.outputs": "increments"}
    assert "DeltaV 0x4010 at 200 Hz" in record["replies"]["ReqOutputConfiguration"]
    with pytest.raises(ConfigMismatch, match=r"^imu\.rate_hz: .*\(200 Hz\), the config 400 Hz"):
        _check(XsensCodec(400.0), ScriptedPort({**XSENS_SCRIPT, REQ_OUTPUT_CONFIGURATION: OUTPUTS_200HZ}))


def test_an_mti_without_delta_v_is_refused_naming_imu_options_outputs():
    port = ScriptedPort({**XSENS_SCRIPT, REQ_OUTPUT_CONFIGURATION: OUTPUTS_NO_DELTA_V})
    with pytest.raises(ConfigMismatch, match=r"^imu\.options\.outputs: the IMU says .*RateOfTurn 0x8020 at 200 Hz' "
                                             r"\(neither\), the config increments"):
        _check(XsensCodec(200.0), port)
    assert port.written[-1] == GO_TO_MEASUREMENT


def test_the_emulated_devices_answer_as_the_documents_say():
    kvh = KvhResponder(Kvh1750Codec(1000.0, gyro_output="rate"))
    assert kvh.answer(b"?DR\r\n") == b""  # normal mode answers no query
    assert kvh.answer(b"=config,1\r") == b"CONFIG,1\r\n" and kvh.configuring
    assert kvh.answer(b"?DR\r\n?ROTFMT\n?FOO\r\n") == b"DR,1000\r\nROTFMT,RATE\r\nINVALID,?FOO\r\n"
    assert kvh.answer(b"=CONFIG,0\r\n") == b"" and not kvh.configuring
    mti = XsensResponder(XsensCodec(200.0))
    assert mti.answer(GO_TO_CONFIG[:3]) == b"" and mti.answer(GO_TO_CONFIG[3:]) == GO_TO_CONFIG_ACK
    assert mti.answer(REQ_OUTPUT_CONFIGURATION) == OUTPUTS_200HZ and mti.configuring
    assert mti.answer(GO_TO_MEASUREMENT) == GO_TO_MEASUREMENT_ACK and not mti.configuring


def test_an_unpowered_emulated_imu_answers_nothing_and_boots_in_its_normal_mode():
    power = {"on": False}
    port = CommandedPty(None, KvhResponder(Kvh1750Codec(200.0)), lambda: power["on"])
    harness = SerialTransport(port.path, 921600, "imu")
    harness.open()
    try:
        exchange = Exchange(harness, timeout_s=0.3)
        with pytest.raises(NoAnswer):
            exchange.ask(b"=CONFIG,1\r\n", lambda buf: reply_line(buf, "CONFIG"), "=CONFIG,1")
        assert not port.responder.configuring
        power["on"] = True
        assert exchange.ask(b"=CONFIG,1\r\n", lambda buf: reply_line(buf, "CONFIG"), "=CONFIG,1") == "CONFIG,1"
        assert port.responder.configuring
        power["on"] = False
        time.sleep(0.3)  # the device's thread sees the power go
        assert not port.responder.configuring
    finally:
        harness.close()
        port.close()


def _harness(tmp_path, cfg: dict, ports: dict, **imu) -> str:
    """The lab config of ``cfg`` on the emulator's ``ports``, its ``imu`` block updated."""
    path = lab_config({**cfg, "imu": {**cfg["imu"], **imu}}, ports, tmp_path)
    return str(path)


def _run(config: str, tmp_path) -> int:
    return main(["run", config, "--duration", "5", "--out", str(tmp_path / "run"), "--viewer", "none", "--quiet",
                 "--no-figures"])


@pytest.mark.parametrize(("device", "harness", "named"), [
    ({"protocol": "kvh1750", "rate_hz": 1000.0, "baudrate": 921600}, {"rate_hz": 200.0},
     "imu.rate_hz: the IMU says 'DR,1000' (1000 Hz), the config 200 Hz"),
    ({"protocol": "kvh1750", "options": {"gyro_output": "rate"}}, {"options": {}},
     "imu.options.gyro_output: the IMU says 'ROTFMT,RATE' (rate), the config delta"),
    ({"protocol": "xsens-mtdata2", "options": {"outputs": "rates"}}, {"options": {}},
     "(rates), the config increments"),
])
def test_an_emulated_imu_set_otherwise_is_exit_2_naming_the_key_before_the_trial(tmp_path, capsys, device, harness,
                                                                                 named):
    cfg = emulated(**{"rate_hz": 200.0, **device})
    with EmulatorThread(parse_config(cfg), speed=1.0, duration=10.0) as emulator:
        code = _run(_harness(tmp_path, cfg, emulator.ports, **harness), tmp_path)
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("hil: error: ") and named in lines[0], lines
    assert not (tmp_path / "run" / "result.json").exists()


def test_an_emulated_trial_records_what_its_imu_said(tmp_path):
    cfg = emulated(200.0, duration_s=3.0)
    cfg["imu"]["options"] = {"gyro_unit": "deg"}
    config = tmp_path / "emulated.yaml"
    config.write_text(yaml.safe_dump(cfg))
    main(["run", str(config), "--speed", "max", "--out", str(tmp_path / "run"), "--viewer", "none", "--quiet",
          "--no-figures"])
    record = json.loads((tmp_path / "run" / "result.json").read_text())["record"]
    assert record["imu_config"]["replies"]["ROTUNITS"] == "ROTUNITS,DEG"
    assert record["imu_config"]["settings"]["imu.rate_hz"] == 200.0


@pytest.mark.xdist_group("lab")
@pytest.mark.skipif(not os.environ.get("HIL_LAB_TESTS"), reason="lab form: set HIL_LAB_TESTS=1")
def test_lab_form_kvh_at_1000_hz_configured_at_200_is_exit_2_within_5_s_naming_imu_rate_hz(tmp_path, capsys):
    cfg = emulated(1000.0, baudrate=921600)
    with Emulator(tmp_path, cfg) as emulator:  # streaming from its start, as powered hardware does
        time.sleep(max(0.0, 1.0 - (time.monotonic() - emulator.started)))
        config = _harness(tmp_path, cfg, emulator.ports, rate_hz=200.0)
        started = time.monotonic()
        code = _run(config, tmp_path)
        took = time.monotonic() - started
        resumed = _frames_within(emulator.ports["imu"], 2.0)
    line = capsys.readouterr().err.strip().splitlines()[0]
    assert code == 2 and took < 5.0, (code, took, line)
    assert line.startswith("hil: error: imu.rate_hz: the IMU says 'DR,1000' (1000 Hz), the config 200 Hz"), line
    assert resumed  # the IMU left its configuration mode: it streams again


def _frames_within(url: str, timeout_s: float) -> bool:
    """Whether KVH frames arrive on ``url`` within ``timeout_s``."""
    port = SerialTransport(url, 921600, "imu")
    port.open()
    try:
        received, deadline = b"", time.monotonic() + timeout_s
        while HEADER not in received and time.monotonic() < deadline:
            received += b"".join(chunk.data for chunk in port.read())
        return HEADER in received
    finally:
        port.close()
