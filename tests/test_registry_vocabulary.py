"""The typed vocabularies of hil/vocabulary.py: the old table-mode letters, the port names and the stream names appear
nowhere else as literals, and the emulated servo speaks the controllers' modes."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from test_servo import servo_at_rest

from hil.vocabulary import Port, Stream, TableMode

ROOT = Path(__file__).resolve().parents[1]
PORT_NAMES = {Port.TABLE_DATA.value, Port.TABLE_CMD.value}
STREAM_NAMES = {Stream.IMU.value, Stream.TABLE.value}
# where "imu" is the config's block (or a unit's default name), not a stream: the modules that write configs
CONFIG_IMU_KEY = {"hil/config.py", "hil/config_units.py", "hil/plan/power.py", "hil/plan/repeatability.py",
                  "emulators/bench.py"}
MODE_LETTERS = re.compile(r"(?!.*(.).*\1)[PRSO]{1,4}")  # the servo's old alphabet: "P", "O", "PRSO", "OPRS", ...


def literals(source: str) -> list[tuple[int, str]]:
    """(line, value) of every mode-letter or port-name string in ``source``; a part of an f-string and the name
    of a ``TypeVar`` are no literal of a vocabulary."""
    tree = ast.parse(source)
    skip = {id(node) for parent in ast.walk(tree) for node in ast.iter_child_nodes(parent)
            if isinstance(parent, ast.JoinedStr)
            or isinstance(parent, ast.Call) and getattr(parent.func, "id", "") == "TypeVar"}
    return sorted((node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip
            and (node.value in PORT_NAMES or MODE_LETTERS.fullmatch(node.value)))


def test_no_mode_letter_or_port_literal_outside_the_vocabulary():
    found = [f"{path.relative_to(ROOT)}:{line}: {value!r}" for package in ("hil", "drivers", "emulators")
             for path in sorted((ROOT / package).rglob("*.py")) if path != ROOT / "hil" / "vocabulary.py"
             for line, value in literals(path.read_text())]
    assert not found, "\n".join(found)


def test_the_check_finds_a_letter_and_a_port_but_no_word():
    source = ('servo.set_mode(axes, "O")\nfor mode in "PRSO": pass\nports["turntable_cmd"]\nR = TypeVar("R")\n'
              'label = f"P{k}"\ncommand = "PPO"\nmode = "position"\n')
    assert literals(source) == [(1, "O"), (2, "PRSO"), (3, "turntable_cmd")]


def stream_literals(source: str) -> list[tuple[int, str]]:
    """(line, value) of every stream name written as a string in ``source``, f-strings' parts left out."""
    tree = ast.parse(source)
    skip = {id(node) for parent in ast.walk(tree) for node in ast.iter_child_nodes(parent)
            if isinstance(parent, ast.JoinedStr)}
    return sorted((node.lineno, node.value) for node in ast.walk(tree) if isinstance(node, ast.Constant)
                  and node.value in STREAM_NAMES and id(node) not in skip)


def test_no_stream_name_is_a_literal_outside_the_vocabulary():
    found = []
    for package in ("hil", "drivers", "emulators"):
        for path in sorted((ROOT / package).rglob("*.py")):
            name = str(path.relative_to(ROOT))
            if name != "hil/vocabulary.py":
                found += [f"{name}:{line}: {value!r}" for line, value in stream_literals(path.read_text())
                          if not (value == Stream.IMU and name in CONFIG_IMU_KEY)]
    assert not found, "\n".join(found)


def test_the_stream_check_finds_a_stream_name_but_not_in_an_f_string():
    source = 'kind = "table"\nif stream == "imu": pass\nlabel = f"imu {k}"\nkey = "turntable"\n'
    assert stream_literals(source) == [(1, "table"), (2, "imu")]


def test_the_emulated_servo_speaks_the_controllers_modes():
    servo = servo_at_rest()
    assert [servo.mode(k) for k in range(3)] == [TableMode.POSITION] * 3
    servo.set_mode([0, 1, 2], "off")
    assert servo.mode(2) is TableMode.OFF and servo.mode(2) == "off"
    with pytest.raises(ValueError, match="'O' is not a valid TableMode"):
        servo.set_mode([0], "O")


@pytest.mark.parametrize("doc", [
    {"imu": "/dev/pts/3", "turntable_data": "/dev/pts/4", "turntable_cmd": "socket://127.0.0.1:5000"},
    {"imu": {"interface": "udp_multicast", "channel": "239.0.0.1"}, "turntable_data": "/dev/pts/4",
     "turntable_cmd": "socket://127.0.0.1:5000", "chamber": "/dev/pts/5", "power": "TCPIP::127.0.0.1::5001::SOCKET"},
    {"units": {"kvh-a": {"imu": "/dev/pts/3"}, "kvh-b": {"imu": "/dev/pts/6"}}, "turntable_data": "/dev/pts/4",
     "turntable_cmd": "socket://127.0.0.1:5000"},
])
def test_the_ports_record_reads_and_writes_ports_json_as_it_was(doc):
    import json

    from hil.vocabulary import DevicePorts

    ports = DevicePorts.of(doc)
    assert json.dumps(ports.as_dict()) == json.dumps(doc)  # the same keys, values and order
    if "units" in doc:
        assert ports.unit("kvh-b").as_dict() == {"imu": "/dev/pts/6", "turntable_data": "/dev/pts/4"}
    else:
        assert (ports.imu, ports.table_cmd) == (doc["imu"], "socket://127.0.0.1:5000") and ports.units == {}
