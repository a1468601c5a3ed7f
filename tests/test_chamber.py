"""The thermal chamber: the Watlow Series F4 driver's Modbus RTU bytes, the emulated F4 on a pty (read and set
by pymodbus's own client), and the emulated chamber's first-order model with its ramp limit."""

from __future__ import annotations

import json
import math
import os
import threading
import tty

import pytest
import yaml
from crccheck.crc import Crc16Modbus

from drivers.crc import crc16_modbus
from drivers.watlow_f4 import ChamberError, WatlowF4, WatlowF4Options
from emulators.chamber import ChamberModel, EmulatedChamber, F4Registers
from hil.cli import main

# Typed from the Modbus specifications: the serial line guide's read-holding-registers example (device 0x11,
# registers 0x006B.., 3 of them) and, for a Series F4 at address 1, reads of 606 (0x025E, decimals), 901
# (0x0385, units), 100 (0x0064, process value) and 300 (0x012C), a write of -40.0 deg C to 300 (-400 = 0xFE70).
SPEC_EXAMPLE = bytes.fromhex("11 03 00 6B 00 03 76 87")
READ_DECIMALS = bytes.fromhex("01 03 02 5E 00 01 E4 60")
DECIMALS_ONE = bytes.fromhex("01 03 02 00 01 79 84")
READ_UNITS = bytes.fromhex("01 03 03 85 00 01 95 A7")
UNITS_C = bytes.fromhex("01 03 02 00 01 79 84")
READ_PV = bytes.fromhex("01 03 00 64 00 01 C5 D5")
PV_23_5 = bytes.fromhex("01 03 02 00 EB F8 0B")
WRITE_SP_MINUS_40 = bytes.fromhex("01 06 01 2C FE 70 08 7B")
READ_SP = bytes.fromhex("01 03 01 2C 00 01 44 3F")
SP_MINUS_40 = bytes.fromhex("01 03 02 FE 70 F9 C0")
ILLEGAL_ADDRESS_REPLY = bytes.fromhex("01 83 02 C0 F1")


class ScriptedDevice:
    """A pty playing a device: answers each expected request with its response, records what it received."""

    def __init__(self, script: list[tuple[bytes, bytes]]) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path, self.received = os.ttyname(self.slave), []
        self.thread = threading.Thread(target=self._play, args=(script,), daemon=True)
        self.thread.start()

    def _play(self, script: list[tuple[bytes, bytes]]) -> None:
        for request, response in script:
            got = b""
            while len(got) < len(request):
                got += os.read(self.master, len(request) - len(got))
            self.received.append(got)
            os.write(self.master, response)

    def close(self) -> None:
        self.thread.join(timeout=2)
        os.close(self.master)
        os.close(self.slave)


def test_crc16_modbus_gives_the_catalogue_check_and_the_specification_example():
    assert crc16_modbus(b"123456789") == 0x4B37 == Crc16Modbus.calc(b"123456789")
    assert crc16_modbus(SPEC_EXAMPLE[:6]).to_bytes(2, "little") == SPEC_EXAMPLE[6:]


def test_the_f4_driver_sends_the_specification_bytes_and_scales_by_the_decimal_setting():
    device = ScriptedDevice([(READ_DECIMALS, DECIMALS_ONE), (READ_UNITS, UNITS_C), (READ_PV, PV_23_5),
                             (WRITE_SP_MINUS_40, WRITE_SP_MINUS_40), (READ_SP, SP_MINUS_40)])
    chamber = WatlowF4(device.path).open()
    try:
        assert chamber.temperature_c() == pytest.approx(23.5)
        chamber.set_set_point_c(-40.0)
    finally:
        chamber.close()
        device.close()
    assert device.received == [READ_DECIMALS, READ_UNITS, READ_PV, WRITE_SP_MINUS_40, READ_SP]


def test_a_set_point_the_controller_does_not_confirm_is_refused():
    device = ScriptedDevice([(READ_DECIMALS, DECIMALS_ONE), (READ_UNITS, UNITS_C),
                             (WRITE_SP_MINUS_40, WRITE_SP_MINUS_40), (READ_SP, bytes.fromhex("01 03 02 00 EB F8 0B"))])
    chamber = WatlowF4(device.path).open()
    try:
        with pytest.raises(ChamberError, match="written -400, read back 235"):
            chamber.set_set_point_c(-40.0)
    finally:
        chamber.close()
        device.close()


def test_a_controller_that_does_not_answer_is_an_error_naming_the_port():
    device = ScriptedDevice([])
    with pytest.raises(ChamberError, match=f"chamber at {device.path}: read register 606"):
        WatlowF4(device.path, WatlowF4Options(timeout_s=0.2)).open()
    device.close()


def _emulated(start_c: float = 25.0, **model) -> tuple[EmulatedChamber, list[float]]:
    now = [0.0]
    model = {"tau_s": 600.0, "ramp_c_per_min_max": 2.0, **model}
    return EmulatedChamber(F4Registers(ChamberModel(start_c=start_c, **model), lambda: now[0])), now


def test_pymodbus_own_client_reads_register_100_and_sets_register_300_of_the_emulated_chamber():
    from pymodbus.client import ModbusSerialClient

    chamber, now = _emulated(start_c=25.0)
    client = ModbusSerialClient(chamber.path, baudrate=19200, timeout=1, retries=0)
    try:
        assert client.connect()
        assert client.read_holding_registers(100, count=1, device_id=1).registers == [250]
        assert not client.write_register(300, (-400) & 0xFFFF, device_id=1).isError()
        assert client.read_holding_registers(300, count=1, device_id=1).registers == [0xFE70]
        now[0] = 60.0  # one minute at the ramp limit: 2 deg C down
        assert client.read_holding_registers(100, count=1, device_id=1).registers == [230]
        assert client.read_holding_registers(4242, count=1, device_id=1).isError()
    finally:
        client.close()
        chamber.close()


def test_the_emulated_chamber_answers_an_unknown_register_with_exception_02():
    registers = F4Registers(ChamberModel(600.0, 2.0, 25.0), lambda: 0.0)
    request = bytes.fromhex("01 03 10 92 00 01")
    assert registers.reply(request + crc16_modbus(request).to_bytes(2, "little")) == ILLEGAL_ADDRESS_REPLY


def test_the_f4_driver_sets_and_reads_the_emulated_chamber_in_deg_f_with_two_decimals():
    chamber, now = _emulated(start_c=20.0)
    chamber.registers.settings.update({606: 2, 901: 0})
    driver = WatlowF4(chamber.path).open()
    try:
        assert driver.temperature_c() == pytest.approx(20.0, abs=0.01)
        driver.set_set_point_c(70.0)
        assert chamber.registers.read(300) == 15800  # 158.00 deg F
        assert driver.set_point_c() == pytest.approx(70.0)
    finally:
        driver.close()
        chamber.close()


def test_the_chamber_model_ramps_at_its_limit_then_follows_the_first_order_step_response():
    tau, ramp = 600.0, 2.0  # s, deg C/min: ramp-limited while the gap exceeds ramp * tau = 20 deg C
    model = ChamberModel(tau, ramp, 25.0)
    model.set_point_c = 85.0
    assert model.advance(600.0) == pytest.approx(45.0)  # 10 min at 2 deg C/min
    ramp_end = (60.0 - 20.0) / (ramp / 60.0)  # 1200 s: the gap is then 20 deg C
    t = ramp_end + 900.0
    assert model.advance(t) == pytest.approx(85.0 - 20.0 * math.exp(-900.0 / tau), abs=1e-9)
    small = ChamberModel(tau, ramp, 25.0)
    small.set_point_c = 35.0  # a 10 deg C step is never ramp-limited
    assert small.advance(300.0) == pytest.approx(35.0 - 10.0 * math.exp(-0.5), abs=1e-9)


def _config(tmp_path, chamber: dict, duration_s: float = 4.0, **errors) -> str:
    data = yaml.safe_load(open("configs/emulated_swing.yaml"))
    data["trial"]["duration_s"] = duration_s
    data["imu"]["errors"].update(errors)
    data["environment"] = {"chamber": chamber}
    path = tmp_path / "chamber.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_a_chamber_that_does_not_answer_ends_a_trial_with_exit_2_naming_the_key_and_port(tmp_path, capsys):
    silent = ScriptedDevice([])
    config = _config(tmp_path, {"controller": "watlow-f4", "port": silent.path, "options": {"timeout_s": 0.2}})
    code = main(["run", config, "--out", str(tmp_path / "out"), "--speed", "max"])
    silent.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [f"hil: error: environment.chamber: chamber at {silent.path}: read register 606: Modbus Error: "
                   "[Input/Output] No response received after 0 retries, continue with next request"]


def test_a_set_point_beyond_the_chamber_limits_is_refused_naming_the_key(tmp_path, capsys):
    config = _config(tmp_path, {"source": "emulator", "set_point_c": 200.0})
    assert main(["run", config, "--out", str(tmp_path / "out"), "--speed", "max"]) == 2
    assert "environment.chamber: set_point_c: 200 deg C is outside limits_c [-70, 180]" in capsys.readouterr().err


def test_an_emulated_trial_in_the_emulated_chamber_reports_the_imu_warming_towards_its_set_point(tmp_path):
    thermal = {"case_tau_s": 20.0, "self_heating_c": 0.0}
    config = _config(tmp_path, {"source": "emulator", "set_point_c": 40.0}, temperature_c=22.0, thermal=thermal)
    main(["run", config, "--out", str(tmp_path / "out"), "--speed", "max", "--no-history"])
    seen = json.loads((tmp_path / "out" / "result.json").read_text())["streams"]["imu_temperature_c"]
    assert seen["min"] == 22.0
    assert seen["max"] == round(40.0 - 18.0 * math.exp(-4.0 / 20.0))  # the KVH 1750 reports whole deg C


@pytest.mark.parametrize("on_exit, after", [("hold", 400), (30.0, 300)])
def test_the_chamber_goes_to_its_on_exit_set_point_when_released(on_exit, after):
    from hil.config_environment import ChamberConfig
    from hil.trial.rig import open_chamber, release_chamber
    from hil.vocabulary import DevicePorts

    cfg = ChamberConfig(source="emulator", set_point_c=40.0, on_exit=on_exit)
    chamber, _ = _emulated(start_c=25.0)
    try:
        controller = open_chamber(cfg, DevicePorts(chamber=chamber.path))
        assert chamber.registers.read(300) == 400
        release_chamber(controller, cfg)
        assert chamber.registers.read(300) == after
    finally:
        chamber.close()


def test_an_exception_reply_is_an_error_naming_the_register():
    device = ScriptedDevice([(READ_DECIMALS, ILLEGAL_ADDRESS_REPLY)])
    with pytest.raises(ChamberError, match=f"chamber at {device.path}: read register 606: refused"):
        WatlowF4(device.path, WatlowF4Options(timeout_s=0.5)).open()
    device.close()


@pytest.mark.parametrize("chamber, message", [
    ({"controller": "nope", "port": "/dev/ttyUSB1"},
     "environment.chamber.controller: 'nope': unknown; chamber controllers: watlow-f4"),
    ({"controller": "watlow-f4", "port": "/dev/ttyUSB1", "options": {"baudrate": 4800}},
     "environment.chamber.options: baudrate: Input should be 9600 or 19200 (the watlow-f4 options)"),
    ({"controller": "watlow-f4"}, "environment.chamber: port: the controller's serial port is needed"),
    ({"source": "emulator", "on_exit": -100},
     "environment.chamber: on_exit: -100 deg C is outside limits_c [-70, 180]"),
])
def test_a_bad_chamber_block_is_refused_naming_its_key(chamber, message):
    from hil.config import ConfigError, parse_config

    data = yaml.safe_load(open("configs/emulated_swing.yaml"))
    data["environment"] = {"chamber": chamber}
    with pytest.raises(ConfigError) as caught:
        parse_config(data)
    assert message in str(caught.value)
