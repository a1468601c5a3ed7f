"""A calibration campaign's part of campaign.html: the headline and the families' statistics per sweep point,
the table of every term's, the errors over their sigma per block (accelerometers, gyros, table) against
N(0, 1), and per sweep point the ratio std(error)/mean(sigma) of every term over its chi-square band (the
figure helpers of :mod:`hil.campaign.campaign_report`)."""

from __future__ import annotations

import html
from typing import Any

import numpy as np

from hil.campaign.campaign_report import (
    band_text,
    banded,
    breakable,
    cell,
    normal_histograms,
    point_cell,
    point_labels,
    table_html,
)
from hil.outputs.html_page import figures_html
from hil.campaign.runs import ERROR, TERM
from hil.campaign.entries import entry_label, entry_rows

BLOCKS = (("accel", "accelerometer terms"), ("gyro", "gyro terms"), ("turntable", "zero offsets"))


def _errors_in_sigmas(rows: list[dict[str, Any]], p: dict, terms: list[str]) -> np.ndarray:
    """Error over sigma of ``terms`` in every done run of a summary entry, pooled (the runs that judge them)."""
    return np.array([row[k] for row in entry_rows(rows, p) if row.get(ERROR) is None for term in terms
                     if row.get(k := f"{TERM}.{term}.error_sigma") is not None], dtype=float)


def _histograms(summary: dict, rows: list[dict[str, Any]], terms: list[str], plt) -> bytes | None:
    panels = []
    for block, name in BLOCKS:
        members = [t for t in terms if t.startswith(f"{block}.")]
        if members:
            panels.append((f"{name}: error / sigma", [_errors_in_sigmas(rows, p, members)
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


def _point_rows(p: dict) -> list[tuple[bool, str]]:
    """A sweep point's rows, one a term; the point spans them."""
    terms = p.get("terms", {})
    rows = []
    for term, s in terms.items():
        cells = point_cell(p, len(terms)) if not rows else ""
        cells += cell(breakable(term), num=False) + cell(s["runs"]) + cell(s["unobservable"])
        cells += "".join(cell(_num(s.get(k))) for k in ("error_mean", "error_std", "sigma_mean"))
        cells += (cell(_num(s.get("ratio"), ".3f"), bold=not s.get("ratio_inside", True))
                  + cell(band_text(s.get("ratio_band"))) + cell(_num(s.get("within_3sigma"), ".2f"))
                  + cell(_num(s.get("z_rms"), ".2f")))
        rows.append((not s.get("ratio_inside", True), cells))
    return rows


def _table(summary: dict) -> str:
    head = ["sweep point", "term", "runs", "un&shy;observable", "error mean", "error std", "mean σ", "std/σ", "band",
            "within 3σ", "rms error/σ"]
    return table_html(head, [row for p in summary["points"] for row in _point_rows(p)])


def _families(summary: dict) -> str:
    head = ("<tr><th>sweep point</th><th>family</th><th>terms</th><th>std/σ min–max</th><th>within 3σ</th>"
            "<th>rms error/σ</th></tr>")
    body = [f"<tr><td>{html.escape(entry_label(p))}</td><td>{html.escape(family)}</td>"
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
        items.append(f"<li>{html.escape(entry_label(p))}: {verdict}, {p['ratio_above']} above and "
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
            f"band, that ratio in bold.</p><h2>Figures</h2>{figures_html(figures)}")
