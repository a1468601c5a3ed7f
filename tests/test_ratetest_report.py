"""``hil report`` of a rate test's output directory: report.html and junit.xml built again from its document."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

from hil.cli import main

ACUTROL = Path(__file__).resolve().parent.parent / "configs" / "ratetest_acutrol.yaml"


def _tested(tmp_path: Path, test: str, settings: dict, *options: str, **limits: float) -> tuple[Path, int]:
    """``hil ratetest TEST`` in simulation on the Acutrol config with ``settings`` and ``limits``: its output
    directory and exit code."""
    doc = yaml.safe_load(ACUTROL.read_text())
    doc[test.replace("-", "_")] = settings
    doc["output"] = {"limits": limits}
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    return out, main(["ratetest", test, str(config), "--simulate", "--out", str(out), "--no-history", *options])


def _failed(out: Path) -> set[str]:
    junit = ET.parse(out / "junit.xml").getroot()
    return {case.get("name") for case in junit.iter("testcase") if case.find("failure") is not None}


def test_report_rebuilds_a_scale_factor_tests_page_and_junit_with_its_verdict(tmp_path, capsys):
    out, code = _tested(tmp_path, "scale-factor", {"rates_dps": [90, 180], "dwell_s": 1, "settle_s": 0.2,
                                                  "axes": ["x"]}, scale_factor_ppm_max=250)
    assert code == 3 and _failed(out) == {"scale_factor_error_x"}  # x: 300 ppm
    page = (out / "report.html").read_text()
    (out / "report.html").unlink()
    (out / "junit.xml").unlink()
    capsys.readouterr()
    assert main(["report", str(out)]) == 3  # its verdict, FAIL
    assert capsys.readouterr().out.strip() == str(out / "report.html")
    assert (out / "report.html").read_text() == page and _failed(out) == {"scale_factor_error_x"}


def test_report_of_a_frequency_response_draws_its_missing_bode_plot(tmp_path):
    out, code = _tested(tmp_path, "frequency-response", {"frequencies_hz": [5, 50, 150], "dwell_s": 0.2,
                                                        "settle_s": 0.2, "axes": ["z"]}, "--no-figures")
    assert code == 0 and not (out / "bode.png").exists()
    assert main(["report", str(out)]) == 0
    page = (out / "report.html").read_text()
    assert (out / "bode.png").exists() and "Frequency response test" in page and "data:image/png" in page
    assert "delay_z" in page and "delay_vs_latch_z" in page


def test_report_of_a_rate_test_document_it_cannot_read_is_one_line_naming_the_file(tmp_path, capsys):
    out, code = _tested(tmp_path, "scale-factor", {"rates_dps": [90, 180], "dwell_s": 1, "settle_s": 0.2,
                                                  "axes": ["z"]}, "--no-figures")
    assert code == 0
    doc = json.loads((out / "scale_factor.json").read_text())
    del doc["axes"]
    (out / "scale_factor.json").write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["report", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(out / "scale_factor.json") in err and "'axes'" in err
