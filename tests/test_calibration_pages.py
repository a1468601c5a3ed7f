"""The calibration's pages as a lab reads them: calibration.html and a calibration's report.html."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from pages import clipped_columns, layout_width, needs_chromium
from test_calibration import run

from hil.cli import main
from hil.estimation.calibration_schedule import default_schedule
from hil.outputs.calibration import calibration_document

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def rate_table(tmp_path_factory) -> Path:
    """The outputs of ``hil calibrate configs/calibration_rate_table.yaml --simulate``, figures drawn."""
    out = tmp_path_factory.mktemp("rate-table") / "out"
    assert main(["calibrate", str(ROOT / "configs" / "calibration_rate_table.yaml"), "--simulate", "--viewer", "none",
                 "--quiet", "--no-history", "--out", str(out)]) == 0
    return out


def test_calibration_html_prints_no_negative_zero_and_heads_its_reasons_as_why_no_estimate(rate_table):
    page = (rate_table / "calibration.html").read_text()
    assert ">-0<" not in page  # the truth of an unfitted misalignment was printed -0
    assert "<th>why no estimate</th>" in page and "<th>unobservable</th>" not in page
    assert "not fitted (left out of calibration.gyro_terms)" in page and "accel_terms / gyro_terms" not in page


def test_a_zero_offset_the_gyros_take_from_the_accelerometers_is_not_called_not_fitted():
    """zero_offset is in the gyro terms; the gyro fit holds the middle and inner offsets at the accelerometers'
    values, so the inner one's reason is the accelerometers' rank and, for the gyros, where it was taken from."""
    windows, acc, gyr = run(default_schedule(dwell_s=2.0, plateau_s=5.0))
    reason = calibration_document(acc, gyr, windows)["unobservable"]["turntable.zero_offset_arcsec.2"]
    assert reason.startswith("accelerometers: not separable") and "not fitted" not in reason
    assert "gyros: taken from the accelerometers" in reason


def test_a_calibrations_report_says_what_it_is_and_leads_with_its_terms(rate_table):
    page = (rate_table / "report.html").read_text()
    assert "Calibration report" in page
    headings = re.findall(r"<h2>(.*?)</h2>", page)
    assert headings[:2] == ["Calibration", "Measurements"], headings
    lead = page[page.index("<h2>Calibration</h2>"):page.index("<h2>Measurements</h2>")]
    assert 'href="calibration.html"' in lead and "calibration_residuals.png" in lead
    # the measurements not judged are folded after the judged ones
    table, folded = page.split("<details>", 1)
    assert "not judged</td>" not in table[table.index("<h2>Measurements</h2>"):]
    assert "measurements not judged" in folded and folded.count("not judged</td>") >= 20


@needs_chromium
@pytest.mark.parametrize("name", ["calibration.html", "report.html"])
def test_the_calibration_pages_fit_1400_px_without_a_clipped_column(rate_table, tmp_path, name):
    page = rate_table / name
    assert layout_width(page, tmp_path) <= 1400
    assert clipped_columns(page, tmp_path) == []
