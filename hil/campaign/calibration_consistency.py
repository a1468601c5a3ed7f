"""A calibration campaign's part of campaign.html: the headline and the families' statistics per sweep point,
the table of every term's, the errors over their sigma per block (accelerometers, gyros, table) against
N(0, 1), and per sweep point the ratio std(error)/mean(sigma) of every term over its chi-square band (the
figure helpers of :mod:`hil.campaign.campaign_report`)."""

from __future__ import annotations

import html
from typing import Any

import numpy as np

from hil.campaign.campaign_report import banded, normal_histograms, point_labels
from hil.outputs.trial_report import figures_html
from hil.campaign.runs import ERROR, TERM
from hil.campaign.task import point_label

BLOCKS = (("accel", "accelerometer terms"), ("gyro", "gyro terms"), ("turntable", "zero offsets"))


def _errors_in_sigmas(rows: list[dict[str, Any]], point: int, terms: list[str]) -> np.ndarray:
    """Error over sigma of ``terms`` in every done run of a point, pooled (the runs that judge them)."""
    return np.array([row[k] for row in rows if row["point"] == point and row.get(ERROR) is None for term in terms
                     if row.get(k := f"{TERM}.{term}.error_sigma") is not None], dtype=float)


def _histograms(summary: dict, rows: list[dict[str, Any]], terms: list[str], plt) -> bytes | None:
    panels = []
    for block, name in BLOCKS:
        members = [t for t in terms if t.startswith(f"{block}.")]
        if members:
            panels.append((f"{name}: error / sigma", [_errors_in_sigmas(rows, p["point"], members)
                                                      for p in summary["points"]]))
    if not panels:
        return None
    return normal_histograms(panels, point_labels(summary["points"]), plt, "Calibration errors against their sigma")


def _ratios(p: dict, label: str, plt) -> bytes:
    tested = [(term, s) for term, s in p["terms"].items() if "ratio" in s]
    return banded([term for term, _ in tested], [s["ratio_band"] for _, s in tested], plt,
                  "95 % band of a consistent estimator", 1.0, "std(error) / mean(sigma)",
                  f"{label}: consistency ratio per term", [(0.0, [s["ratio"] for _, s in tested], "ratio")])


def _num(v: Any, form: str = ".3g") -> str:
    return "–" if v is None else format(v, form)


def _table(summary: dict) -> str:
    head = ("<tr><th>sweep point</th><th>term</th><th>runs</th><th>unobservable</th><th>error mean</th>"
            "<th>error std</th><th>mean σ</th><th>std/σ</th><th>band</th><th>within 3σ</th><th>rms error/σ</th></tr>")
    body = []
    for p in summary["points"]:
        for term, s in p.get("terms", {}).items():
            flag = "" if s.get("ratio_inside", True) else " class='row-FAIL'"
            band = f"{s['ratio_band'][0]:.3f}–{s['ratio_band'][1]:.3f}" if "ratio_band" in s else "–"
            cells = [s["runs"], s["unobservable"]] + [_num(s.get(k)) for k in ("error_mean", "error_std", "sigma_mean")]
            cells += [_num(s.get("ratio"), ".3f"), band, _num(s.get("within_3sigma"), ".2f"),
                      _num(s.get("z_rms"), ".2f")]
            body.append(f"<tr{flag}><td>{html.escape(point_label(p['values']))}</td><td>{html.escape(term)}</td>"
                        + "".join(f"<td class='num'>{c}</td>" for c in cells) + "</tr>")
    return f"<div class='wide'><table><thead>{head}</thead><tbody>{''.join(body)}</tbody></table></div>"


def _families(summary: dict) -> str:
    head = ("<tr><th>sweep point</th><th>family</th><th>terms</th><th>std/σ min–max</th><th>within 3σ</th>"
            "<th>rms error/σ</th></tr>")
    body = [f"<tr><td>{html.escape(point_label(p['values']))}</td><td>{html.escape(family)}</td>"
            f"<td class='num'>{f['terms']}</td><td class='num'>{f['ratio_min']:.3f}–{f['ratio_max']:.3f}</td>"
            f"<td class='num'>{f['within_3sigma']:.2f}</td><td class='num'>{f['z_rms']:.2f}</td></tr>"
            for p in summary["points"] for family, f in p.get("families", {}).items()]
    return f"<div class='wide'><table><thead>{head}</thead><tbody>{''.join(body)}</tbody></table></div>"


def _headlines(summary: dict) -> str:
    items = []
    for p in summary["points"]:
        if not p.get("ratio_tested"):
            continue
        worst = p["worst"]
        verdict = "consistent" if p["consistent"] else "NOT consistent"
        items.append(f"<li>{html.escape(point_label(p['values']))}: {verdict}, {p['ratio_above']} above and "
                     f"{p['ratio_below']} below their band of {p['ratio_tested']} terms (by chance "
                     f"~{p['ratio_expected_outside']:.1f}, at most {p['ratio_outside_allowed']}); worst {html.escape(worst['term'])} "
                     f"{worst['ratio']:.3f}</li>")
    return f"<ul>{''.join(items)}</ul>" if items else "<p>Too few runs for statistics.</p>"


def calibration_section(summary: dict, rows: list[dict[str, Any]], plt) -> str:
    """A calibration campaign's part of the page: the headlines, the tables, the histograms, the ratios."""
    terms = list(dict.fromkeys(t for p in summary["points"] for t in p.get("terms", {})))
    figures = [("Error over reported sigma per block, every sweep point, against N(0, 1)",
                _histograms(summary, rows, terms, plt))]
    figures += [(f"{label}: std(error)/mean(sigma) per term with the 95 % band of a consistent estimator",
                 _ratios(p, label, plt))
                for p, label in zip(summary["points"], point_labels(summary["points"])) if p.get("ratio_tested")]
    return (f"<h2>Calibration consistency per sweep point</h2>{_headlines(summary)}{_families(summary)}"
            f"<h2>Every term</h2>{_table(summary)}"
            "<p class='meta'>Units as in calibration.json; a row is highlighted when its ratio falls outside its "
            f"band.</p><h2>Figures</h2>{figures_html(figures)}")
