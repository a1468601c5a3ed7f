"""report.html: self-contained, every figure embedded, measurements judged against the config's limits."""

from __future__ import annotations

import base64
import html
import json
import math
import re
import shutil
import xml.etree.ElementTree as ET

import pytest
import yaml
from tests.helpers import PAPER_ERRORS, make_config, run_estimator

from hil.config import ReportLimits
from hil.outputs.figures import FIGURES
from hil.outputs.measurements import FAIL, NOT_JUDGED, PASS, format_value, measurements, overall
from hil.outputs.trial_report import ReportError, write_report
from hil.outputs.result import build_result, summary_text, write_result
from hil.outputs.trial_outputs import write_trial_outputs
from hil.samples import StreamCounts


TRUTH = {"accel_bias_ug": PAPER_ERRORS["accel_bias_ug"], "accel_drift_ug_per_h": [0.0] * 3}  # as emulated_truth


@pytest.fixture(scope="module")
def trial_dir(tmp_path_factory):
    """Outputs of a 60 s emulated swing: result.json, series.csv, the figures, config.yaml."""
    cfg = make_config(duration=60.0, rate=100.0, errors=PAPER_ERRORS)
    est = run_estimator(cfg, solve_period=1.0)
    n = est.solution().samples
    result = _document(build_result("report-test", est, StreamCounts(n, n, n, dropped=3), TRUTH))
    out = tmp_path_factory.mktemp("trial")
    write_trial_outputs(out, result, est.snapshots, ReportLimits(), figures=True)
    return out, result


def _document(result: dict) -> dict:
    """``build_result``'s document as a completed trial files it: with how it ended and the calibration it
    applied."""
    return {"trial": result["trial"], "ended": "completed", "calibration_applied": None, **result}


def _outcomes(page: str) -> dict[str, str]:
    """measurement name -> outcome cell text, parsed from the report's table."""
    rows = re.findall(r"<tr class='row-[^']*'><td><code>([^<]+)</code>.*?<td class='outcome [^']*'>([^<]+)</td></tr>", page)
    return dict(rows)


def test_report_is_self_contained_with_every_figure_embedded(trial_dir):
    out, _ = trial_dir
    path = write_report(out, ReportLimits())
    assert path == out / "report.html"
    page = path.read_text(encoding="utf-8")
    assert not re.search(r"https?://", page)
    assert not re.search(r"<(link|script)\b", page)
    embedded = [base64.b64decode(b) for b in re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", page)]
    assert sorted(embedded) == sorted((out / name).read_bytes() for name in FIGURES)
    assert all(src.startswith("data:image/png;base64,") for src in re.findall(r"src='([^']*)'", page))


def test_limits_that_pass_and_limits_that_fail_are_judged(trial_dir):
    out, result = trial_dir
    sigma = max(result["estimate"]["accel_bias_sigma_ug"])
    page = write_report(out, ReportLimits(bias_sigma_ug_max=2 * sigma, dropped_max=5)).read_text()
    outcomes = _outcomes(page)
    assert outcomes["accel_bias_sigma_x"] == outcomes["frames_dropped"] == PASS
    assert outcomes["converged_at"] == NOT_JUDGED
    assert "class=\"verdict PASS\"" in page

    page = write_report(out, ReportLimits(bias_sigma_ug_max=2 * sigma, dropped_max=2)).read_text()
    outcomes = _outcomes(page)
    assert outcomes["accel_bias_sigma_y"] == PASS and outcomes["frames_dropped"] == FAIL
    assert "class=\"verdict FAIL\"" in page and "1 failed: frames_dropped" in page


def test_limits_come_from_the_config_copy_beside_the_result(trial_dir, tmp_path):
    out, result = trial_dir
    shutil.copytree(out, tmp_path / "run")
    error_x = abs(result["estimate"]["accel_bias_ug"][0] - 60.0)
    config = make_config(duration=60.0).model_dump(mode="json", exclude_none=True)
    config["output"] = {"limits": {"bias_error_ug_max": error_x / 2, "method2_error_deg_max": 10.0}}
    (tmp_path / "run" / "config.yaml").write_text(yaml.safe_dump(config))
    page = write_report(tmp_path / "run").read_text()
    outcomes = _outcomes(page)
    assert outcomes["accel_bias_error_x"] == FAIL
    assert outcomes["alignment_method2_pitch"] == outcomes["alignment_method2_roll"] == PASS
    assert outcomes["accel_bias_sigma_x"] == NOT_JUDGED


def test_missing_figures_are_drawn_from_the_series(trial_dir, tmp_path):
    out, _ = trial_dir
    shutil.copytree(out, tmp_path / "run")
    for name in FIGURES:
        (tmp_path / "run" / name).unlink()
    page = write_report(tmp_path / "run", ReportLimits()).read_text()
    images = re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", page)
    assert len(images) == len(FIGURES)
    assert all(base64.b64decode(b).startswith(b"\x89PNG") for b in images)
    assert not any((tmp_path / "run" / name).exists() for name in FIGURES)


def _junit(out) -> dict[str, ET.Element]:
    """testcase name -> element of out/junit.xml, after checking the JUnit elements, attributes and counts."""
    root = ET.parse(out / "junit.xml").getroot()
    assert root.tag == "testsuites"
    (suite,) = root.findall("testsuite")
    cases = suite.findall("testcase")
    failures = [c.find("failure") for c in cases if c.find("failure") is not None]
    skipped = [c for c in cases if c.find("skipped") is not None]
    errors = [c for c in cases if c.find("error") is not None]
    for element in (root, suite):
        assert element.get("name") == "report-test"
        assert int(element.get("tests")) == len(cases) and int(element.get("failures")) == len(failures)
        assert int(element.get("errors")) == len(errors) and int(element.get("skipped")) == len(skipped)
        assert float(element.get("time")) == pytest.approx(60.0)
    assert all(c.get("name") and c.get("classname") == "hil.report-test" for c in cases)
    assert all(f.get("message") and f.get("type") for f in failures)
    return {c.get("name"): c for c in cases}


def test_junit_xml_has_a_testcase_per_judged_measurement(trial_dir):
    out, result = trial_dir
    sigma = result["estimate"]["accel_bias_sigma_ug"]
    write_report(out, ReportLimits(bias_sigma_ug_max=2 * max(sigma), dropped_max=5))
    cases = _junit(out)
    assert sorted(cases) == ["accel_bias_sigma_x", "accel_bias_sigma_y", "accel_bias_sigma_z", "frames_dropped"]
    assert all(len(case) == 0 for case in cases.values())  # passed: no failure, no skipped

    write_report(out, ReportLimits(bias_sigma_ug_max=min(sigma), dropped_max=2))
    cases = _junit(out)
    assert cases["frames_dropped"].find("failure").get("message") == "frames_dropped = 3 frames, limit ≤ 2 frames"
    worst = "xyz"[sigma.index(max(sigma))]
    message = cases[f"accel_bias_sigma_{worst}"].find("failure").get("message")
    assert f"= {format_value(max(sigma))} µg" in message and f"limit ≤ {format_value(min(sigma))} µg" in message
    assert len(cases["accel_bias_sigma_" + "xyz"[sigma.index(min(sigma))]]) == 0


def test_junit_xml_skips_a_limit_that_does_not_apply(trial_dir, tmp_path):
    out, result = trial_dir
    shutil.copytree(out, tmp_path / "run")
    no_truth = {key: value for key, value in result.items() if key != "truth"}
    (tmp_path / "run" / "result.json").write_text(json.dumps(no_truth))
    write_report(tmp_path / "run", ReportLimits(bias_error_ug_max=10.0))
    (case,) = _junit(tmp_path / "run").values()
    assert case.get("name") == "accel_bias_error" and "no truth" in case.find("skipped").get("message")


def test_junit_xml_reports_a_trial_that_did_not_complete_as_an_error(trial_dir, tmp_path):
    out, result = trial_dir
    shutil.copytree(out, tmp_path / "run")
    (tmp_path / "run" / "result.json").write_text(json.dumps({**result, "ended": "interrupted: SIGTERM"}))
    write_report(tmp_path / "run", ReportLimits(dropped_max=5))
    cases = _junit(tmp_path / "run")
    assert cases["trial_completed"].find("error").get("message") == "trial interrupted: SIGTERM"
    assert len(cases["frames_dropped"]) == 0


def test_a_judged_measurement_without_a_value_fails():
    static = {
        "trial": {"name": "static", "duration_s": 60.0, "samples": 6000},
        "streams": {"dropped": 0, "corrupt": 0},
        "estimate": {"accel_bias_ug": None, "accel_bias_sigma_ug": None, "observable": False, "gram_rank": 9,
                     "converged_at_s": None},
        "alignment_deg": {"method1": None, "method2": None, "theoretical": None},
    }  # fmt: skip
    judged = measurements(static, ReportLimits(bias_sigma_ug_max=10.0, corrupt_max=0))
    by_name = {m.name: m for m in judged}
    assert by_name["accel_bias_sigma_z"].outcome == FAIL and by_name["accel_bias_sigma_z"].value is None
    assert by_name["frames_corrupt"].outcome == PASS
    assert by_name["converged_at"].outcome == NOT_JUDGED
    assert overall(judged) == FAIL
    assert overall(measurements(static, ReportLimits(corrupt_max=0))) == PASS


def test_a_directory_without_result_json_is_refused(tmp_path):
    with pytest.raises(ReportError, match="result.json: not found"):
        write_report(tmp_path)


@pytest.mark.parametrize("content, reason", [(b"[1, 2]", "not a trial result"), (b"{\xff}", "not valid JSON")])
def test_a_result_json_that_is_not_a_result_is_refused(tmp_path, content, reason):
    (tmp_path / "result.json").write_bytes(content)
    with pytest.raises(ReportError, match=reason):
        write_report(tmp_path)


@pytest.mark.parametrize("block, key, value, field", [
    ("estimate", "accel_bias_sigma_ug", ["2.0", "2.0", "2.0"], "estimate.accel_bias_sigma_ug.0"),
    ("estimate", "observable", None, "estimate.observable"),
    ("trial", "samples", 1.5, "trial.samples"),
])
def test_a_result_json_of_another_shape_is_refused_naming_its_field(trial_dir, tmp_path, block, key, value, field):
    """Judged as it stands, a sigma written as a string would stop the report half-way, and a block this
    version does not know would be ignored: the report names the first field it cannot read instead."""
    shutil.copytree(trial_dir[0], tmp_path / "run")
    result = trial_dir[1]
    (tmp_path / "run" / "result.json").write_text(json.dumps({**result, block: {**result[block], key: value}}))
    with pytest.raises(ReportError, match=rf"not a trial result of this version \({re.escape(field)}: "):
        write_report(tmp_path / "run", ReportLimits(bias_sigma_ug_max=10.0))
    assert not (tmp_path / "run" / "report.html").exists() or (tmp_path / "run" / "report.html").read_bytes() == \
        (trial_dir[0] / "report.html").read_bytes()


def _no_constant(name):
    raise ValueError(f"result.json holds {name}, which is not JSON")


def test_result_json_is_strict_json_and_the_report_reads_its_nulls(tmp_path):
    cfg = make_config(duration=60.0, rate=100.0, kind="static", errors=PAPER_ERRORS)
    est = run_estimator(cfg, solve_period=1.0)
    n = est.solution().samples
    result = _document(build_result("static", est, StreamCounts(n, n, n), TRUTH))
    assert result["estimate"]["observable"] is False  # static: a singular Gram matrix
    result["estimate"]["gram_condition"] = math.inf  # what a Gram matrix with a zero eigenvalue reports
    write_trial_outputs(tmp_path, result, est.snapshots, ReportLimits(), figures=False)
    loaded = json.loads((tmp_path / "result.json").read_text(), parse_constant=_no_constant)
    assert loaded["estimate"]["gram_condition"] is None and loaded["estimate"]["observable"] is False
    (tmp_path / "nested").mkdir()
    write_result(tmp_path / "nested", {"values": [math.nan, {"low": -math.inf}, 1.5]})
    nested = json.loads((tmp_path / "nested" / "result.json").read_text(), parse_constant=_no_constant)
    assert nested == {"values": [None, {"low": None}, 1.5]}

    page = write_report(tmp_path, ReportLimits(bias_sigma_ug_max=10.0)).read_text()  # figures drawn from the series
    outcomes = _outcomes(page)
    assert outcomes["gram_condition"] == NOT_JUDGED and outcomes["accel_bias_sigma_x"] == FAIL
    assert len(re.findall(r"src='data:image/png;base64,", page)) == len(FIGURES)


@pytest.mark.parametrize("kind, observable", [("swing", True), ("static", False)])
def test_the_summary_says_not_observable_only_when_it_is_not(tmp_path, kind, observable):
    cfg = make_config(duration=120.0, rate=100.0, kind=kind, errors=PAPER_ERRORS)
    est = run_estimator(cfg, solve_period=1.0)
    n = est.solution().samples
    result = build_result(kind, est, StreamCounts(n, n, n), None)
    assert result["estimate"]["observable"] is observable
    text = summary_text(result, tmp_path)
    assert ("NOT observable" in text) is not observable
    assert ("accelerometer bias (ug):" in text) is observable


def test_a_calibration_trial_summarises_its_calibration(tmp_path):
    cfg = make_config(duration=60.0, rate=100.0, kind="static", errors=PAPER_ERRORS)
    est = run_estimator(cfg, solve_period=1.0)
    n = est.solution().samples
    result = build_result("calibration", est, StreamCounts(n, n, n), None)
    result["calibration"] = {"file": "calibration.json", "positions": 18, "residual_rms_ug": 0.72,
                             "residual_max_ug": 1.63, "unobservable": ["turntable.zero_offset_arcsec.2"],
                             "worst_error_sigma": 3.07}
    text = summary_text(result, tmp_path)
    assert "calibration over 18 positions: residual 0.72 ug RMS, 1.63 ug max" in text
    assert "3.07 sigma" in text and "unobservable: turntable.zero_offset_arcsec.2" in text
    assert str(tmp_path / "calibration.json") in text
    assert "accelerometer bias" not in text  # the swing estimator's lines mean nothing for a static schedule


def _streams(**counts) -> dict:
    """The aligned streams of 10 000 IMU samples with the given counts."""
    base = {"aligner_aligned": 10_000, "aligner_imu_filled": 0, "aligner_imu_bridged": 0, "imu_gated": 0,
            "aligner_without_angles": 0, "sync_offset_ms": 0.01}
    return {"streams": {**base, **counts}}


@pytest.mark.parametrize(("counts", "failing"), [
    ({}, set()),
    ({"aligner_imu_filled": 6, "aligner_imu_bridged": 6}, {"imu_missing_fraction"}),  # 12 of 10 006
    ({"imu_gated": 11}, {"imu_gated_fraction"}),
    ({"aligner_without_angles": 11}, {"imu_without_angles_fraction"}),
    ({"sync_offset_ms": -2.6}, {"sync_offset"}),  # half a period at 200 Hz is 2.5 ms
])
def test_the_judged_data_fail_each_over_its_default_limit_naming_it(counts, failing):
    limits = make_config(rate=200.0).limits
    assert limits.sync_offset_ms_max == pytest.approx(2.5)
    results = {m.name: m for m in measurements(_streams(**counts), limits)}
    judged = {"imu_missing_fraction", "imu_gated_fraction", "imu_without_angles_fraction", "sync_offset"}
    assert judged <= set(results)
    assert {name for name in judged if results[name].outcome == FAIL} == failing
    assert all(results[name].outcome == PASS for name in judged - failing)


def test_a_sync_offset_without_motion_is_not_judged_and_a_simulation_judges_no_stream():
    results = {m.name: m for m in measurements(_streams(sync_offset_ms=None), make_config().limits)}
    assert results["sync_offset"].outcome == NOT_JUDGED and "no motion" in results["sync_offset"].description
    simulated = {"streams": {"imu_frames": 10, "aligned": 10}}
    assert not {m.name for m in measurements(simulated, make_config().limits)} & {"imu_gated_fraction", "sync_offset"}


@pytest.mark.parametrize("ended", ["completed", "early: no data from any device for 10 s", "interrupted: SIGTERM"])
def test_the_report_says_first_how_the_trial_ended(trial_dir, tmp_path, ended):
    shutil.copytree(trial_dir[0], tmp_path / "run")
    (tmp_path / "run" / "result.json").write_text(json.dumps({**trial_dir[1], "ended": ended}))
    page = write_report(tmp_path / "run", ReportLimits()).read_text()
    body = page[page.index("<body"):]
    assert re.search(r"<p class=\"ended [a-z]+\">Trial ([^<]+)\.</p>", body).group(1) == html.escape(ended)
