"""The index of a trial of several units (docs/contracts.md, "Output files"; docs/units.md): OUT/result.json with
each unit's headline figures, OUT/report.html linking each unit's report, OUT/junit.xml with each unit's
testsuite; each unit's own outputs are in ``OUT/units/<name>/``, as a one-unit trial writes them."""

from __future__ import annotations

import html
import json
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path

from hil.outputs.html_page import REPORT_NAME, html_page
from hil.outputs.junit import JUNIT_NAME
from hil.outputs.measurements import FAIL, PASS, format_value
from hil.outputs.page_header import page_header
from hil.outputs.result import COMPLETED, ENDED_EARLY, INTERRUPTED, TrialEnd, verdict_exit_code

UNITS_DIR = "units"  # OUT/units/<name>/: a unit's outputs
SEVERITY = (PASS, FAIL, ENDED_EARLY, INTERRUPTED)  # the trial's verdict is its units' worst
ABSENT = "ABSENT"  # the verdict of an optional unit whose port could not be opened: no trial, not judged
COUNTS = ("tests", "failures", "errors", "skipped")  # junit.xml's counts, summed over the units' testsuites


def unit_entry(name: str, result: dict) -> dict:
    """A unit's line of the index result.json, from its written result.json document."""
    estimate, truth, record = (result.get(key) or {} for key in ("estimate", "truth", "record"))
    return {"name": name, "out_dir": f"{UNITS_DIR}/{name}", "dut_serial": record.get("dut_serial"),
            "ended": result["ended"], "verdict": result.get("verdict"),
            "accel_bias_ug": estimate.get("accel_bias_ug"), "accel_bias_sigma_ug": estimate.get("accel_bias_sigma_ug"),
            "converged_at_s": estimate.get("converged_at_s"), "truth_accel_bias_ug": truth.get("accel_bias_ug")}


def absent_entry(name: str, dut_serial: str | None, why: str) -> dict:
    """The line of an optional unit that was absent (``why``: its port's error): no outputs, no verdict of its own."""
    return {"name": name, "out_dir": None, "dut_serial": dut_serial, "ended": f"absent: {why}", "verdict": ABSENT,
            "accel_bias_ug": None, "accel_bias_sigma_ug": None, "converged_at_s": None, "truth_accel_bias_ug": None}


def units_exit_code(verdicts: Iterable[str]) -> int:
    """The exit code of a trial of several units of ``verdicts`` (docs/contracts.md, "Exit codes"): 1 if any unit
    did not complete, else 3 if any FAILs, else 0; an absent optional unit counts for nothing."""
    codes = {verdict_exit_code(verdict) for verdict in verdicts if verdict != ABSENT}
    return 1 if 1 in codes else max(codes)


def write_units_index(out: Path, name: str, entries: list[dict]) -> dict:
    """Write the index of the trial ``name`` over its units' ``entries`` (:func:`unit_entry`, :func:`absent_entry`);
    its result.json. The trial's verdict is its present units' worst."""
    present = [entry for entry in entries if entry["verdict"] != ABSENT]
    early = [entry["name"] for entry in present if entry["ended"] != COMPLETED]
    ended = str(TrialEnd.early(f"unit {', '.join(early)} did not complete")) if early else COMPLETED
    verdict = max((entry["verdict"] for entry in present), key=SEVERITY.index)
    doc = {"trial": {"name": name}, "ended": ended, "verdict": verdict, "units": entries}
    (out / "result.json").write_text(json.dumps(doc, indent=2) + "\n")
    (out / REPORT_NAME).write_text(_index_page(doc))
    _write_junit(out, name, entries)
    print(f"{name}: {len(entries)} units, {verdict} ({out / REPORT_NAME})")
    return doc


def _index_page(doc: dict) -> str:
    """report.html: the trial's verdict, a row per unit with its verdict and bias, linking its report."""
    e = html.escape
    rows = []
    for unit in doc["units"]:
        bias, sigma, truth = unit["accel_bias_ug"], unit["accel_bias_sigma_ug"], unit["truth_accel_bias_ug"]
        shown = ", ".join(f"{format_value(b, s)} ± {format_value(s)}" for b, s in zip(bias, sigma)) if bias and sigma \
            else "—"
        truth_shown = ", ".join(format_value(t) for t in truth) if truth else "—"
        link = f"<a href='{e(unit['out_dir'])}/{REPORT_NAME}'>{e(unit['name'])}</a>" if unit["out_dir"] else \
            e(unit["name"])
        rows.append(f"<tr><td>{link}</td><td>{e(unit['dut_serial'] or '—')}</td>"
                    f"<td>{e(unit['ended'])}</td><td class='outcome {e(unit['verdict'])}'>{e(unit['verdict'])}</td>"
                    f"<td class='num'>{e(shown)}</td><td class='num'>{e(truth_shown)}</td></tr>")
    table = ("<div class='wide'><table><thead><tr><th>unit</th><th>serial</th><th>ended</th><th>verdict</th>"
             "<th>accelerometer bias (µg)</th><th>truth (µg)</th></tr></thead>"
             f"<tbody>{''.join(rows)}</tbody></table></div>")
    name = doc["trial"]["name"]
    header = page_header("trial of several units", name, ended=doc["ended"], verdict=doc["verdict"])
    return html_page(header, f"{name}: {len(doc['units'])} units", table)


def _write_junit(out: Path, name: str, entries: list[dict]) -> None:
    """junit.xml: each unit's testsuite (from its own junit.xml), named ``<trial>/<unit>``; an absent unit's a
    skipped test saying why."""
    root = ET.Element("testsuites", name=name)
    for entry in entries:
        unit = entry["name"]
        if entry["out_dir"] is None:
            suite = ET.SubElement(root, "testsuite", name=f"{name}/{unit}", tests="1", failures="0", errors="0",
                                  skipped="1")
            ET.SubElement(ET.SubElement(suite, "testcase", classname=f"{name}/{unit}", name="present"), "skipped",
                          message=entry["ended"])
            continue
        for suite in ET.parse(out / UNITS_DIR / unit / JUNIT_NAME).getroot().iter("testsuite"):
            suite.set("name", f"{name}/{unit}")
            root.append(suite)
    for count in COUNTS:
        root.set(count, str(sum(int(suite.get(count, "0")) for suite in root)))
    ET.indent(root)
    (out / JUNIT_NAME).write_bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n")
