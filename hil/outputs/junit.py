"""``junit.xml`` beside report.html: the trial's limits as JUnit test cases for CI (Jenkins, GitLab,
junitparser).

One ``<testsuite>`` (the trial) in ``<testsuites>``; one ``<testcase>`` per measurement that has a
limit in ``output.limits``. A FAIL carries ``<failure>`` whose message holds the value and the limit.
A limit that does not apply to this trial (the bias error without truth) is ``<skipped>``: CI reads
skipped as a test that exists but was not run. A measurement without a limit is informational, not a
test, and is left out: reported as skipped, the dozens of them would bury the few judged cases (and
CI would flag every run as having skipped tests). A trial that did not complete (``ended`` early or
interrupted) adds a ``trial_completed`` case with an ``<error>`` holding the reason. The trial's record (the
unit, operator, station, software, config digest, times, host) is the suite's ``<properties>``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from hil.outputs.measurements import FAIL, NOT_JUDGED, Measurement
from hil.outputs.record import PROPERTIES
from hil.outputs.result import COMPLETED

JUNIT_NAME = "junit.xml"


def write_junit(out_dir: Path, result: dict, results: list[Measurement]) -> Path:
    """Write ``out_dir/junit.xml`` for the measurements of a result.json document; returns its path."""
    trial = result.get("trial") or {}
    name = str(trial.get("name", "trial"))
    cases = [m for m in results if m.limit]
    ended = result.get("ended", COMPLETED)
    counts = {
        "tests": len(cases) + (ended != COMPLETED),
        "failures": sum(m.outcome == FAIL for m in cases),
        "errors": int(ended != COMPLETED),
        "skipped": sum(m.outcome == NOT_JUDGED for m in cases),
        "time": trial.get("duration_s") or 0.0,
    }
    attrs = {"name": name, **{k: str(v) for k, v in counts.items()}}
    root = ET.Element("testsuites", attrs)
    suite = ET.SubElement(root, "testsuite", attrs)
    record = result.get("record") or {}
    if record:
        properties = ET.SubElement(suite, "properties")
        for key in PROPERTIES:
            if record.get(key) is not None:
                ET.SubElement(properties, "property", name=key, value=str(record[key]))
    if ended != COMPLETED:
        case = ET.SubElement(suite, "testcase", name="trial_completed", classname=f"hil.{name}")
        ET.SubElement(case, "error", message=f"trial {ended}", type="ended")
    for m in cases:
        case = ET.SubElement(suite, "testcase", name=m.name, classname=f"hil.{name}")
        if m.outcome == FAIL:
            value = "no value" if m.value is None else f"{m.shown} {m.unit}".rstrip()
            failure = ET.SubElement(case, "failure", message=f"{m.name} = {value}, limit {m.limit} {m.unit}".rstrip(),
                                    type="limit")  # fmt: skip
            failure.text = m.description
        elif m.outcome == NOT_JUDGED:
            ET.SubElement(case, "skipped", message=m.description)
    ET.indent(root)
    path = Path(out_dir) / JUNIT_NAME
    path.write_bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n")
    return path
