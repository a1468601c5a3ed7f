"""A plan's pages: ``OUT/plan.html`` (every step with its verdict and a link to its report, each unit's turn-on
repeatability with the biases of the repeats drawn) and ``OUT/junit.xml`` (a testsuite per step: a trial step's
own cases, any other step one case that fails when the step did not complete)."""

from __future__ import annotations

import html
import xml.etree.ElementTree as ET
from typing import Any

from hil.outputs.page_header import page_header
from hil.plan.state import PlanState, write_atomically

AXES = "xyz"
STYLE = ("body{font-family:sans-serif;margin:1.5em;max-width:1100px}table{border-collapse:collapse}"
         "td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left;white-space:nowrap}.PASS{color:#070}.FAIL{color:#b00}"
         ".INTERRUPTED,.ENDED.EARLY{color:#b60}")


def write_pages(state: PlanState) -> None:
    """plan.html and junit.xml of the plan in ``state``."""
    write_atomically(state.out / "plan.html", plan_page(state.doc, state))
    write_atomically(state.out / "junit.xml", plan_junit(state))


def plan_page(doc: dict[str, Any], state: PlanState) -> str:
    e = html.escape
    rows = "".join(_step_row(entry, state) for entry in doc["steps"])
    units = "".join(_unit_section(name, figures) for name, figures in doc["units"].items())
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>plan {e(doc['name'])}</title>"
            f"<style>{STYLE}</style></head><body>"
            f"{page_header('test plan', doc['name'], {'started_utc': doc['started_utc']}, doc['ended'], doc['verdict'])}"
            f"<p>run {e(doc['run'])} · config {e(doc['config'])}</p><h2>Steps</h2><table><tr><th>step</th><th>kind"
            f"</th><th>repeat</th><th>started (UTC)</th><th>ended (UTC)</th><th>ended</th><th>verdict</th>"
            f"<th>outputs</th></tr>{rows}</table>{units}</body></html>\n")


def _step_row(entry: dict[str, Any], state: PlanState) -> str:
    e = html.escape
    out = entry.get("out_dir")
    link = ""
    if out:
        page = next((name for name in ("report.html",) if (state.out / out / name).is_file()), None)
        link = f"<a href='{e(out)}/{page}'>{e(out)}/{page}</a>" if page else e(out)
    repeat = f"step {entry['repeat_of']}, pass {entry['pass']}" if entry.get("repeat_of") else ""
    verdict = entry["verdict"] or ""
    cells = (entry["index"], entry["kind"], repeat, entry["started_utc"] or "", entry["ended_utc"] or "",
             entry["ended"] or "not run")
    return ("<tr>" + "".join(f"<td>{e(str(cell))}</td>" for cell in cells)
            + f"<td class='{e(verdict)}'>{e(verdict)}</td><td>{link}</td></tr>")


def _unit_section(name: str, figures: dict[str, Any]) -> str:
    e = html.escape
    truth = figures.get("truth_turn_on_bias_ug")
    rows = "".join(
        f"<tr><td>{axis}</td><td>{figures['turn_on_repeatability_ug'][k]:.2f}</td>"
        f"<td>{figures['turn_on_repeatability_ci_ug'][k][0]:.2f} to {figures['turn_on_repeatability_ci_ug'][k][1]:.2f}"
        f"</td><td>{figures['in_run_sigma_ug'][k]:.2f}</td>{f'<td>{truth[k]:g}</td>' if truth else ''}</tr>"
        for k, axis in enumerate(AXES))
    return (f"<h2>Unit {e(name)}: turn-on-to-turn-on bias repeatability</h2><p>{figures['power_ons']} power-ons; "
            f"interval {figures['confidence']:.0%} (chi-square)</p><table><tr><th>axis</th><th>repeatability (ug, "
            f"1&sigma;)</th><th>interval (ug)</th><th>in-run &sigma; (ug)</th>"
            f"{'<th>emulated truth (ug, 1&sigma;)</th>' if truth else ''}</tr>{rows}</table>"
            f"{_bias_plot(figures['biases_ug'])}")


def _bias_plot(biases: list[list[float]], width: int = 600, height: int = 90) -> str:
    """Each axis's bias at each power-on, as an inline SVG strip about its mean."""
    strips = []
    for k, axis in enumerate(AXES):
        values = [row[k] for row in biases]
        mean, span = sum(values) / len(values), max(max(values) - min(values), 1e-9)
        step = (width - 80) / max(len(values) - 1, 1)
        points = " ".join(f"{60 + i * step:.1f},{height / 2 - (v - mean) / span * (height - 30):.1f}"
                          for i, v in enumerate(values))
        strips.append(f"<svg width='{width}' height='{height}' role='img' aria-label='bias {axis} per power-on'>"
                      f"<text x='4' y='{height / 2:.0f}'>{axis}</text><text x='4' y='{height - 4}' font-size='11'>"
                      f"mean {mean:.1f} ug, span {span:.2f} ug</text><polyline fill='none' stroke='#36c' "
                      f"points='{points}'/>" + "".join(f"<circle cx='{p.split(',')[0]}' cy='{p.split(',')[1]}' "
                                                        f"r='3' fill='#36c'/>" for p in points.split()) + "</svg>")
    return "<h3>Bias at each power-on</h3>" + "<br>".join(strips)


def plan_junit(state: PlanState) -> str:
    """junit.xml: a testsuite per step, named ``NN-<kind>``."""
    root = ET.Element("testsuites", name=state.doc["name"])
    for entry in state.doc["steps"]:
        name = f"{entry['index']:02d}-{entry['kind']}"
        own = state.out / (entry.get("out_dir") or "-") / "junit.xml"
        suite = ET.parse(own).getroot().find("testsuite") if own.is_file() else None
        if suite is None:
            suite = ET.Element("testsuite", tests="1", failures="0", skipped=str(int(entry["ended"] is None)),
                               errors=str(int(entry["ended"] not in ("completed", None))))
            case = ET.SubElement(suite, "testcase", name="step_completed", classname=f"plan.{name}")
            if entry["ended"] is None:
                ET.SubElement(case, "skipped", message="not run")
            elif entry["ended"] != "completed":
                ET.SubElement(case, "error", message=entry["ended"], type="ended")
        suite.set("name", name)
        root.append(suite)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"
