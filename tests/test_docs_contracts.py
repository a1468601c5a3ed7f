"""The contract pages carry what the code offers: every configuration key in docs/contracts.md, "Configuration",
every command and option in its "Commands", every registered protocol in docs/wire-formats.md."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from pydantic import BaseModel

from drivers.registry import CODECS_BUILT_IN as CODECS
from hil.cli import build_parser
from hil.config import Config

DOCS = Path(__file__).resolve().parent.parent / "docs"


def section(page: str, heading: str) -> str:
    """The text of ``## heading`` in docs/``page`` up to the next heading of that level."""
    text = (DOCS / page).read_text(encoding="utf-8")
    match = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", text, re.MULTILINE | re.DOTALL)
    assert match, f"docs/{page} has no section {heading!r}"
    return match.group(1)


def code_words(text: str) -> set[str]:
    """Every identifier inside a `code span` of ``text``."""
    return {w for span in re.findall(r"`([^`]+)`", text) for w in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", span)}


def _types(annotation) -> list:
    """An annotation and the types inside it (``list[X] | None``: the list, X and None)."""
    return [annotation, *(t for arg in getattr(annotation, "__args__", ()) for t in _types(arg))]


def config_keys(model: type[BaseModel] = Config, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """The key path of every field of the configuration, blocks and leaves."""
    keys = []
    for name, field in model.model_fields.items():
        path = (*prefix, name)
        keys.append(path)
        nested = [a for a in _types(field.annotation) if isinstance(a, type) and issubclass(a, BaseModel)]
        for sub in nested:
            keys += config_keys(sub, path)
    return keys


def test_every_configuration_key_is_documented():
    words = code_words(section("contracts.md", "Configuration"))
    missing = [".".join(path) for path in config_keys() if not set(path) <= words]
    assert not missing, f"keys missing from docs/contracts.md, \"Configuration\": {missing}"


def test_every_command_and_option_is_documented():
    text = section("contracts.md", "Commands")
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    missing = []
    for name, sub in commands.items():
        if f"`hil {name}" not in text:
            missing.append(f"hil {name}")
        options = [o for a in sub._actions for o in a.option_strings if o.startswith("--") and o != "--help"]
        missing += [f"hil {name} {o}" for o in options if not re.search(rf"(?<![\w-]){o}(?![\w-])", text)]
    assert not missing, f"missing from docs/contracts.md, \"Commands\": {missing}"


def test_every_registered_protocol_has_a_section():
    text = (DOCS / "wire-formats.md").read_text(encoding="utf-8")
    headings = re.findall(r"^## (.+)$", text, re.MULTILINE)
    missing = [name for name in CODECS if not any(h == name or h.endswith(f"(`{name}`)") for h in headings)]
    assert not missing, f"protocols without a section in docs/wire-formats.md: {missing}"


def test_an_undocumented_key_is_found():
    class Block(BaseModel):
        dut_serial: str = ""

    class Top(BaseModel):
        record: Block = Block()

    assert config_keys(Top) == [("record",), ("record", "dut_serial")]
    assert not {"record", "dut_serial"} <= code_words("`record.dut_part` and `dut_serialx`")
