"""A trial's measurements are computed once, from result.json as written, and that one list makes its verdict,
report.html, junit.xml and the viewer's last ``/verdict``."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

from emulators.simulation import Simulation
from hil.config import ReportLimits
from hil.outputs import measurements as measurements_module
from hil.outputs.judgement import as_written, judge
from hil.outputs.measurements import DECLARED
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.trial.outcome import TrialOutcome
from hil.viewer.verdict import final_markdown
from tests.helpers import make_config

LIMITS = ReportLimits(bias_sigma_ug_max=1e-9, dropped_max=0)  # the bias's sigma FAILs, the frames dropped PASS


def _outcome(tmp_path) -> TrialOutcome:
    """A 30 s simulated swing judged against ``LIMITS``."""
    cfg = make_config(duration=30.0)
    cfg = cfg.model_copy(update={"output": cfg.output.model_copy(update={"limits": LIMITS})})
    processor = TrialProcessor(PipelineSettings.of(cfg))
    for batch in Simulation.from_config(cfg).batches():
        processor.feed_batch(batch)
    return TrialOutcome.of(processor.finished(), cfg, "", tmp_path / "out")


def test_a_trials_measurements_are_computed_once_for_every_output(tmp_path, monkeypatch):
    outcome = _outcome(tmp_path)
    made = []
    build = measurements_module.Measurement.__init__
    monkeypatch.setattr(measurements_module.Measurement, "__init__",
                        lambda self, *args, **kwargs: (made.append(self), build(self, *args, **kwargs))[1])
    judged = outcome.write(figures=False)
    page = (outcome.out / "report.html").read_text()
    listed = int(re.search(r"of (\d+) measurements judged", page).group(1))
    assert len(made) == listed == len(judged.measurements) > 20  # once, not again for the report


def test_the_verdict_report_junit_and_viewer_read_the_one_judgement(tmp_path):
    outcome = _outcome(tmp_path)
    judged = outcome.write(figures=False)
    failed = [m.name for m in judged.measurements if m.outcome == "FAIL"]
    assert judged.verdict == outcome.result["verdict"] == "FAIL"
    assert failed == ["accel_bias_sigma_x", "accel_bias_sigma_y", "accel_bias_sigma_z"]
    cases = {case.get("name"): case for case in ET.parse(outcome.out / "junit.xml").getroot().iter("testcase")}
    assert sorted(name for name, case in cases.items() if case.find("failure") is not None) == failed
    assert set(cases) == {m.name for m in judged.measurements if m.limit}
    assert f"{len(failed)} failed: {', '.join(failed)}" in (outcome.out / "report.html").read_text()
    last = final_markdown(judged)
    assert last.startswith("## Verdict: FAIL\n")
    assert all(f"| `{name}` |" in last and "**FAIL**" in last for name in failed)
    assert judge(as_written(outcome.result), LIMITS) == judged  # what hil report makes of the same files


def test_every_limit_of_a_trial_judges_a_declared_measurement():
    declared = {d.limit for d in DECLARED if d.limit is not None}
    rate_tests = {"scale_factor_ppm_max", "nonlinearity_ppm_max", "asymmetry_ppm_max"}  # hil ratetest's documents
    assert declared == set(ReportLimits.model_fields) - rate_tests
    names = [d.name for d in DECLARED if d.name]
    assert len(names) == len(set(names))  # each declared once
