"""Values are shown to their sigma's precision, and the same text in junit.xml (which the CI plugin prints) and
report.html: one formatting function, never a float's seventeen digits."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import pytest
from tests.helpers import PAPER_ERRORS, make_config, run_estimator

from hil.config import ReportLimits
from hil.outputs.measurements import format_value
from hil.outputs.result import build_result
from hil.outputs.trial_outputs import write_trial_outputs
from hil.outputs.trial_report import write_report
from hil.samples import StreamCounts


@pytest.mark.parametrize("value, sigma, shown", [
    (5.4168178643328035, None, "5.42"),  # no sigma: three significant digits
    (-58.33092485662986, 1.53, "-58.3"),  # the sigma's two significant digits set the decimals
    (60.31234, 0.15, "60.31"),
    (1234.5678, 23.0, "1235"),
    (-0.004, 2.0, "0.0"),  # never -0.0
    (4000.0, None, "4000"),
    (0.01, None, "0.01"),
    (0.000123456, None, "1.23e-04"),
    (3, None, "3"),
])
def test_a_value_is_shown_to_its_sigmas_precision_else_to_three_significant_digits(value, sigma, shown):
    assert format_value(value, sigma) == shown


@pytest.fixture(scope="module")
def swing(tmp_path_factory):
    """A 60 s emulated swing's outputs, judged against limits its sigmas and errors fail."""
    cfg = make_config(duration=60.0, rate=100.0, errors=PAPER_ERRORS)
    est = run_estimator(cfg, solve_period=1.0)
    n = est.solution().samples
    result = {"trial": {}, "ended": "completed", "calibration_applied": None,
              **build_result("precision", est, StreamCounts(n, n, n), {"accel_bias_ug": PAPER_ERRORS["accel_bias_ug"],
                                                                        "accel_drift_ug_per_h": [0.0] * 3})}
    limits = ReportLimits(bias_sigma_ug_max=0.01, bias_error_ug_max=0.01)
    out = tmp_path_factory.mktemp("precision")
    write_trial_outputs(out, result, est.snapshots, limits, figures=False)
    write_report(out, limits)
    return out, result


def test_junit_and_the_report_show_a_failed_value_to_its_sigmas_precision(swing):
    out, result = swing
    sigma = result["estimate"]["accel_bias_sigma_ug"]
    error = result["estimate"]["accel_bias_ug"][0] - PAPER_ERRORS["accel_bias_ug"][0]
    messages = {c.get("name"): c.find("failure").get("message")
                for c in ET.parse(out / "junit.xml").getroot().iter("testcase") if c.find("failure") is not None}
    assert messages["accel_bias_sigma_x"] == f"accel_bias_sigma_x = {sigma[0]:.3g} µg, limit ≤ 0.01 µg"
    decimals = 1 - int(f"{sigma[0]:e}".split("e")[1])  # two significant digits of the sigma
    assert messages["accel_bias_error_x"] == f"accel_bias_error_x = {error:.{decimals}f} µg, limit |x| ≤ 0.01 µg"
    assert not re.search(r"\d\.\d{6,}", " ".join(messages.values()))
    page = (out / "report.html").read_text(encoding="utf-8")
    row = re.search(r"<code>accel_bias_error_x</code>.*?<td class='num'>([^<]+)</td>", page).group(1)
    assert row == f"{error:.{decimals}f}"
