"""The typed vocabularies of hil/vocabulary.py: the old table-mode letters and the port names appear nowhere else
as literals, and the emulated servo speaks the controllers' modes."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from test_servo import servo_at_rest

from hil.vocabulary import Port, TableMode

ROOT = Path(__file__).resolve().parents[1]
PORT_NAMES = {Port.TABLE_DATA.value, Port.TABLE_CMD.value}
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


def test_the_emulated_servo_speaks_the_controllers_modes():
    servo = servo_at_rest()
    assert [servo.mode(k) for k in range(3)] == [TableMode.POSITION] * 3
    servo.set_mode([0, 1, 2], "off")
    assert servo.mode(2) is TableMode.OFF and servo.mode(2) == "off"
    with pytest.raises(ValueError, match="'O' is not a valid TableMode"):
        servo.set_mode([0], "O")
