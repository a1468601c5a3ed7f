"""The Acutrol command language (TM-8004): the grammar, the reply framing, the emulated Acutrol answering the
lines that public clients send, and the harness's own lines checked against the grammar."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from tests.helpers import make_config

from drivers.acl import AclCommand, AclError, AclReply, ReplyReader, format_message, frame_reply, parse_message
from drivers.acutrol_controller import AcutrolController, AcutrolOptions, mode_of
from drivers.table_controller import TableError
from emulators.acutrol_table import AcutrolTable
from emulators.motion import motion_from_config
from emulators.servo import Servo
from emulators.table_server import ServoPort
from hil.cli import main

ROOT = Path(__file__).resolve().parents[1]
# Lines written after the patterns of two public clients (IEAv-EFO/acutrol3000 python/acutrol3000.py, a
# GPIB client; williamsea/Acutrol Acutrol/Form1.cs, a C# client): lower-case short forms, chained reads,
# the limit's mode first, one-letter mnemonics, spaces after commas and around ';'.
CLIENT_LINES = [
    "*idn?", ":Interlock:Reset", ":mode:off 1", ":int:close 1", ":dem:osc 1,0,0,0", ":mode:synt 1",
    ":mode:rate 1", ":dem:rate 1,0", ":interlock? 1", "*stb?", ":limit:absolute? 1",
    ":limit:acc? pos,1", ":limit:acc? rate,1", ":limit:rate? synt,1", ":lim:acc pos,1,45", ":lim:rate rate,1,25",
    ":lim:rate synt,1,25", ":mode? 1", ":mode 1,pos", ":dem:pos 1,12.5", ":dem:delta 1,-2.5", ":mode 1,rate",
    ":read:pos? 1;rate? 1;acc? 1", ":read:pos? 1", ":read:rate? 1", ":con:osc 1,Enable,2.0,0.1,Pos,Lin",
    ":M:P 1", ":D:P 1, 3.5", ":u:f f ; :R:P 1", ":R:R 1", ":M:S 1", ":D:O 1, 2, 0.1, 0", ":L:L P,1,-170;:L:H P,1,170",
    ":L:R P,1,30", ":L:A P,1,50", ":I:O 1", ":I:C 1", ":I:R", ":M:O 1",
    # the manual's own examples (TM-8004 2.1-2.3, 4.5-4.7)
    ":Demand:Position 3,10.5", ":Dem:Pos 3,10.50000", ":D:P 3,10.5", ":Mode:Position 1;Rate 2",
    ":Dem:Pos 2,0.01;:Mode:Pos 2;Rate 1", ":M? 1;:M? 2;:M? 3", ":INT:CLOSe 1", ":I:C 1;C 2", ":MODE:OFF 1", ":M:O 2;O 3",
    ":LIM:HPOS P,2,59.0", ":L:H? 2", ":Config:Event 1,1,1,20,+,45.125", ":con:ev 1,2,360",
]
LIMITS = {"position_min_deg": [-180, -60, -180], "position_max_deg": [180, 60, 180],
          "rate_dps": [30, 20, 40], "accel_dps2": [50, 50, 50]}


def table(reply_mode: str = "framed") -> AcutrolTable:
    cfg = make_config(duration=10.0, kind="static", turntable={"limits": LIMITS})
    servo = Servo(cfg.turntable, 200.0, motion_from_config(cfg.turntable.motion))
    return AcutrolTable(servo, AcutrolOptions(reply_mode=reply_mode))


def ask(emulated: AcutrolTable, line: str) -> AclReply:
    (reply,) = ReplyReader().feed(emulated.answer(line.encode()))
    return reply


def test_a_reply_is_framed_as_the_acl_response_block():
    # TM-9374 3.4.2: the error code and the text length as 32-bit words (least significant byte first, TM-8004
    # 2.4), then the text and a NUL; written out by hand
    assert frame_reply(AclReply("P;R")) == b"\x00\x00\x00\x00\x03\x00\x00\x00P;R\x00"
    assert frame_reply(AclReply("bad", 3)) == b"\x03\x00\x00\x00\x03\x00\x00\x00bad\x00"
    assert frame_reply(AclReply()) == b"\x00" * 8 + b"\x00"
    reader = ReplyReader()
    block = b"\x00\x00\x00\x00\x05\x00\x00\x0012.50\x00\x02\x00\x00\x00\x01\x00\x00\x00x\x00"
    assert reader.feed(block[:7]) == [] and reader.feed(block[7:13]) == []
    assert reader.feed(block[13:]) == [AclReply("12.50"), AclReply("x", 2)]


def test_short_and_long_forms_and_any_case_are_one_command():
    same = [parse_message(line) for line in (":Demand:Position 3,10.5", ":Dem:Pos 3,10.50000", ":D:P 3,10.5",
                                             ":dem:pos 3,10.5", "Demand:Position 3,10.5")]
    assert all(units == [AclCommand("Demand:Position", ("3", 10.5))] for units in same)
    assert parse_message(":Mode:Position 1;Rate 2") == [AclCommand("Mode:Position", ("1",)),
                                                         AclCommand("Mode:Rate", ("2",))]
    assert parse_message(":read:pos? 1;rate? 1") == [AclCommand("Read:Position", ("1",), True),
                                                     AclCommand("Read:Rate", ("1",), True)]
    assert parse_message(":L:R P,1,120") == [AclCommand("Limit:Rate", ("Position", "1", 120.0))]
    assert parse_message(":R:P 2") == [AclCommand("Read:Position", ("2",), True)]  # Act2000: no '?' needed
    assert format_message([AclCommand("Mode:Off", ("3",)), AclCommand("Mode:Off", ("2",))]) == \
        b":Mode:Off 3;:Mode:Off 2\n"


@pytest.mark.parametrize(("line", "code"), [
    (":Demand:Posn 3,10.5", 2), (":Dem;Pos 3,10.50000", 2), (":D:P,3,10.5", 2),  # the manual's three errors
    (":Mode? ALL", 3), (":Mode 4,Position", 3), (":Mode 1,Fast", 3), (":Demand:Position 1,nan", 1),
    (":Demand:Rate 1", 1), (":Limit:Rate 1,20", 1), (":Configure:Sync ON", 2), (":Mode:Position 1;Spin 2", 2)])
def test_the_grammar_refuses_what_the_manual_does(line, code):
    with pytest.raises(AclError) as refused:
        parse_message(line)
    assert refused.value.code == code


def test_the_lines_public_clients_send_are_all_answered_as_the_manual_says():
    emulated, replies = table(), {}
    for line in CLIENT_LINES:
        replies[line] = ask(emulated, line)
        emulated.servo.commit(emulated.servo.horizon + 5.0)  # the clients wait between commands; so does the table
    assert {line: r.text for line, r in replies.items() if not r.ok} == {}
    fields = replies["*idn?"].text.split(",")
    assert len(fields) == 4 and "Acutrol3000" in fields[1]  # manufacturer, model, serial, software
    assert replies[":interlock? 1"].text == "Close" and replies["*stb?"].text == "0"
    assert replies[":mode? 1"].text == "Rate"  # after :mode:rate 1, a word
    assert replies[":M? 1;:M? 2;:M? 3"].text == "Rate;Position;Position"  # as the chain before it set them
    pos, rate, acc = (float(v) for v in replies[":read:pos? 1;rate? 1;acc? 1"].text.split(";"))
    assert (pos, rate, acc) == (pytest.approx(12.5 - 2.5), 0.0, 0.0)  # at the position demand less the delta, still
    assert float(replies[":limit:acc? pos,1"].text) == 50.0 and float(replies[":limit:rate? synt,1"].text) == 40.0
    assert float(replies[":L:H? 2"].text) == 59.0
    assert len(replies[":limit:absolute? 1"].text.split(",")) == 6
    assert all(r.text == "" for line, r in replies.items() if "?" not in line and line not in (":u:f f ; :R:P 1",
                                                                                              ":R:R 1"))
    assert float(replies[":R:R 1"].text) == 0.0
    assert [m for m in emulated.modes().split(",")] == ["Off", "Off", "Off"]  # :M:O 1 and :M:O 2;O 3 at the end


def test_a_mode_answer_is_read_as_a_word_or_its_letter():
    assert [mode_of(a) for a in ("Position", "P", "Rate\n", "r", "Synthesis", "S", "Off", "O")] == [
        "position", "position", "rate", "rate", "synthesis", "synthesis", "off", "off"]
    assert mode_of("Track") == "track"  # a mode the harness never commands stays itself: not off


def test_queries_only_mode_answers_queries_alone_and_flags_errors_in_the_status_byte():
    emulated = table("queries-only")
    assert emulated.answer(b":Mode:Position 1") == b""
    assert emulated.answer(b":Mode? 1;:Mode? 2") == b"Position;Position\n"
    assert emulated.answer(b":Demand:Position 2,95") == b""  # beyond the middle axis' 60 deg: refused
    assert emulated.answer(b"*STB?") == b"192\n"  # bit 7 (an error) and bit 6 (the summary)
    assert emulated.answer(b"*STB?") == b"0\n"  # reading clears it
    client = AcutrolController("emulated", make_config(duration=1.0).turntable.limits,
                               AcutrolOptions(reply_mode="queries-only")).open(ServoPort(emulated))
    assert client.identify().startswith("turntable-hil") and client.interlocks_closed("inner")
    with pytest.raises(TableError, match="status byte 192 flags an error"):
        client.send(AclCommand("Demand:Position", ("2", 95.0)))
    client.close()
    assert emulated.modes() == "Off,Off,Off"


def _judge_log(log: list) -> set[str]:
    """Every message of an emulated table's log parsed against the grammar; none refused; the paths used."""
    assert log and [(line, code) for line, code in log if code] == []
    return {unit.path for line, _ in log for unit in parse_message(line)}


def test_a_swing_with_table_control_speaks_only_the_language(tmp_path):
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["turntable"]["command_port"] = "emulator"
    path = tmp_path / "swing.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    main(["run", str(path), "--duration", "12", "--speed", "max", "--quiet", "--viewer", "none", "--no-figures",
          "--out", str(out)])
    paths = _judge_log(json.loads((out / "emulator.json").read_text())["table_log"])
    assert {"Limit:Rate", "Limit:Lowposition", "Demand:Oscillator", "Mode:Synthesis", "Mode:Off", "Mode",
            "Interlock"} <= paths


def test_hil_calibrate_speaks_only_the_language(tmp_path):
    cfg = yaml.safe_load((ROOT / "configs" / "calibration_short.yaml").read_text())
    cfg["calibration"].update(positions=6, plateau_s=2, dwell_s=1)
    cfg["turntable"]["command_port"] = "emulator"
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    assert main(["calibrate", str(path), "--speed", "max", "--quiet", "--viewer", "none", "--no-figures",
                 "--out", str(out)]) in (0, 3)
    paths = _judge_log(json.loads((out / "emulator.json").read_text())["table_log"])
    assert {"Demand:Position", "Mode:Position", "Mode:Rate", "Demand:Rate", "Mode:Off"} <= paths
