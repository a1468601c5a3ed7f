"""The trial's record (who tested which unit, where, with which software and config, when): result.json ``record``,
report.html's header and junit.xml's ``<properties>``, from the config's ``record`` block and the command line."""

from __future__ import annotations

import hashlib
import json
import socket
import xml.etree.ElementTree as ET
from datetime import datetime
from pathlib import Path

import yaml

from hil.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_a_trials_record_is_in_result_report_and_junit_with_the_command_line_over_the_config(tmp_path):
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["trial"]["duration_s"] = 20
    cfg["record"] = {"dut_part": "KVH-1750", "dut_serial": "from-config", "operator": "jo", "notes": "after repair"}
    config = tmp_path / "trial.yaml"
    config.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    before = datetime.now().astimezone()
    assert main(["simulate", str(config), "--out", str(out), "--no-figures", "--dut", "SN 0042",
                 "--station", "bay 2"]) in (0, 3)
    record = json.loads((out / "result.json").read_text())["record"]
    assert {k: record[k] for k in ("dut_part", "dut_serial", "operator", "station", "notes")} == {
        "dut_part": "KVH-1750", "dut_serial": "SN 0042", "operator": "jo", "station": "bay 2", "notes": "after repair"}
    assert record["config_sha256"] == hashlib.sha256(config.read_text().encode()).hexdigest()
    assert record["host"] == socket.gethostname() and record["software_version"]
    started, ended = (datetime.fromisoformat(record[k]) for k in ("started_utc", "ended_utc"))
    assert before.replace(microsecond=0) <= started <= ended and started.utcoffset().total_seconds() == 0
    properties = {p.get("name"): p.get("value")
                  for p in ET.parse(out / "junit.xml").getroot().iter("property")}
    assert properties["dut_serial"] == "SN 0042" and properties["station"] == "bay 2"
    assert properties["config_sha256"] == record["config_sha256"] and "notes" not in properties
    report = (out / "report.html").read_text()
    assert "<th>dut_serial</th><td>SN 0042</td>" in report and "<th>operator</th><td>jo</td>" in report


def test_an_unknown_record_key_is_one_line_naming_it(tmp_path, capsys):
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["record"] = {"serial": "x"}
    config = tmp_path / "trial.yaml"
    config.write_text(yaml.safe_dump(cfg))
    assert main(["simulate", str(config), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "record.serial" in err, err
