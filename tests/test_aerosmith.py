"""The Ideal Aerosmith rate table: its command set answered by the emulated table as the public client expects,
a rate test commanded through it, and a trial it cannot perform refused before anything moves."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from tests.helpers import make_config

from drivers.aerosmith_controller import AerosmithController, AerosmithOptions
from drivers.table_controller import InterlockError, TableError
from emulators.aerosmith_table import AerosmithTable
from emulators.motion import motion_from_config
from emulators.servo import Servo
from emulators.table_server import ServoPort
from hil.cli import main

ROOT = Path(__file__).resolve().parents[1]
LIMITS = {"rate_dps": [60, 60, 60], "accel_dps2": [30, 30, 30]}


def emulated(**turntable) -> AerosmithTable:
    cfg = make_config(duration=10.0, kind="static", turntable={"limits": LIMITS, **turntable})
    return AerosmithTable(Servo(cfg.turntable, 200.0, motion_from_config(cfg.turntable.motion)), AerosmithOptions())


def request(table: AerosmithTable, command: str) -> str:
    """As RateSweepGUI's ``request``: the command and CR LF, then a reply line and a prompt line (read to CR)."""
    reply, prompt = table.feed(command.encode() + b"\r\n").decode().split("\r")[:2]
    assert prompt.strip() == ">"
    return reply.strip()


def test_the_public_clients_commands_are_answered_with_a_reply_and_a_prompt():
    table = emulated()
    assert request(table, "STA") == "5"  # holding its position, drive enabled
    for command in ("VEL20", "ACL30", "DIR1", "HOF0.500000", "SAV", "CYC0", "AMP2.000000", "FRQ0.500000"):
        assert request(table, command) == "OK"
    assert request(table, "MOV12") == "OK"
    table.servo.commit(5.0)
    assert float(request(table, "PPO")) == pytest.approx(12.0) and float(request(table, "PVE")) == 0.0
    assert request(table, "MCO1") == "1" and int(request(table, "STA")) == 4 | 1  # position, enabled, still
    assert table.feed(b"JOG-10\r\n") == b""  # a jog answers nothing; the client reads on at its next command
    table.servo.commit(10.0)
    assert float(request(table, "PVE")) == pytest.approx(-10.0) and int(request(table, "STA")) == 4 | 2 | 16
    assert table.feed(b"STO") == b""  # stop acts without a line end, and answers nothing
    table.servo.commit(20.0)
    assert int(request(table, "STA")) == 4 and float(request(table, "PVE")) == 0.0
    assert table.feed(b"SGO\r\n") == b""
    assert int(request(table, "STA")) & 3 == 3
    assert [line for line, code in table.log if code] == []
    assert request(table, "XYZ1").startswith("ERR") and request(table, "CYC3").startswith("ERR")


def test_the_controller_drives_the_emulated_table_and_ends_off():
    table = emulated()
    cfg = make_config(turntable={"limits": LIMITS})
    with AerosmithController("emulated", cfg.turntable.limits).open(ServoPort(table)) as client:
        client.apply_limits()
        assert client.interlocks_closed("outer")
        client.set_mode("outer", "rate")
        client.demand_rate("outer", 10.0)
        with pytest.raises(TableError, match="does not command the 'inner' axis"):
            client.demand_rate("inner", 1.0)
        table.servo.commit(3.0)
        assert client.read_position("outer") == pytest.approx(table.servo.reading(0)[0])
    assert table.modes() == "Off" and table.offs == 1
    assert [line for line, _ in table.log] == ["VEL60", "ACL30", "STA", "STA", "JOG10.000000", "PPO", "STO", "STA"]


def test_ctrl_c_inside_a_session_still_stops_the_table():
    table = emulated()
    cfg = make_config(turntable={"limits": LIMITS})
    with pytest.raises(KeyboardInterrupt), AerosmithController("emulated", cfg.turntable.limits).open(
            ServoPort(table)) as client:
        client.set_mode("outer", "rate")
        client.demand_rate("outer", -20.0)
        raise KeyboardInterrupt
    assert [line for line, _ in table.log][-3:] == ["JOG-20.000000", "STO", "STA"] and table.modes() == "Off"


def test_open_interlocks_keep_the_table_still():
    table = emulated(interlock_trip_at_s=0.0)
    table.servo.advance(0.0)
    cfg = make_config(turntable={"limits": LIMITS})
    client = AerosmithController("emulated", cfg.turntable.limits).open(ServoPort(table))
    with pytest.raises(InterlockError):
        client.set_mode("outer", "rate")
    with pytest.raises(TableError, match="refused MOV"):
        client.demand_position("outer", 5.0)
    client.close()
    assert table.modes() == "Off"


def test_a_three_axis_swing_on_the_rate_table_is_refused_before_anything_moves(tmp_path, capsys):
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["turntable"].update(command_port="emulator", controller="aerosmith")
    path = tmp_path / "swing.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--viewer", "none", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "turns one axis (outer, controller_options.axis)" in err
    assert "middle, inner" in err and "nothing was sent" in err
    assert not (tmp_path / "out" / "emulator.json").exists()
    cfg["turntable"]["controller_options"] = {"axis": "sideways"}
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--viewer", "none", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "turntable.controller_options: axis: Input should be" in err
    assert "(the aerosmith options)" in err


def test_a_rate_test_on_the_emulated_rate_table_recovers_the_bias(tmp_path):
    out = tmp_path / "out"
    assert main(["run", str(ROOT / "configs" / "rate_table_aerosmith.yaml"), "--duration", "60", "--speed", "max",
                 "--quiet", "--viewer", "none", "--no-figures", "--out", str(out)]) == 0
    doc = json.loads((out / "result.json").read_text())
    reference = doc["table_reference"]
    for bias, sigma, truth in zip(reference["accel_bias_ug"], reference["accel_bias_sigma_ug"],
                                  doc["truth"]["accel_bias_ug"]):
        assert abs(bias - truth) <= 3.0 * sigma
    stats = json.loads((out / "emulator.json").read_text())
    assert stats["table_modes"] == "Off" and stats["table_modes_off"] == 1
    assert [line for line, code in stats["table_log"]] == ["VEL60", "ACL30", "STA", "JOG10.000000", "STO", "STA"]


@pytest.mark.parametrize(("protocol", "message"), [
    ("kvh1750", "turntable.data_protocol: 'kvh1750': unknown; table data protocols: tts1"),
    ("tts9", "turntable.data_protocol: 'tts9': unknown; table data protocols: tts1")])
def test_the_table_data_protocol_is_a_table_codec_of_the_registry(tmp_path, capsys, protocol, message):
    cfg = yaml.safe_load((ROOT / "configs" / "rate_table_aerosmith.yaml").read_text())
    cfg["turntable"]["data_protocol"] = protocol
    path = tmp_path / "rate.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--viewer", "none", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_a_calibration_that_turns_three_axes_is_refused_on_the_rate_table(tmp_path, capsys):
    cfg = yaml.safe_load((ROOT / "configs" / "calibration_short.yaml").read_text())
    cfg["turntable"]["controller"] = "aerosmith"
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["calibrate", str(path), "--simulate", "--viewer", "none", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the trial moves the middle, inner axis too; nothing was sent" in err


def test_the_gyro_rate_test_of_hil_calibrate_on_the_rate_table_is_within_3_sigma(tmp_path):
    from hil.outputs.calibration_report import comparison

    out = tmp_path / "out"
    assert main(["calibrate", str(ROOT / "configs" / "calibration_rate_table.yaml"), "--simulate", "--viewer", "none",
                 "--no-figures", "--quiet", "--out", str(out)]) == 0
    judged = {r["term"]: r["error_sigma"] for r in comparison(json.loads((out / "calibration.json").read_text()))
              if r["error_sigma"] is not None}
    assert {"gyro.bias_dph.2", "gyro.scale_ppm.2"} <= set(judged) and all(abs(e) <= 3.0 for e in judged.values())
