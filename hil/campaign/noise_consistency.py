"""A noise campaign's part of campaign.html: the table of fitted terms against the truth per sweep point, the
fitted/truth histograms per term, and per term the coverage of the reported intervals with its binomial band
(drawn with the figure helpers of :mod:`hil.campaign.campaign_report`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from hil.campaign.noise_summary import AXES, TERM_KEYS
from hil.campaign.campaign_report import (
    band_text,
    banded,
    breakable,
    cell,
    png,
    point_cell,
    point_labels,
    table_html,
)
from hil.campaign.entries import entry_rows
from hil.outputs.html_page import figures_html
from hil.campaign.runs import ERROR, TRUTH

AXIS_NAMES = "xyz"


def _terms(summary: dict) -> list[str]:
    """The terms some sweep point has statistics of (a truth and resolved runs), in noise.json's order."""
    found = {term for p in summary["points"] for term, per_axis in p.get("terms", {}).items()
             if any("coverage" in a for a in per_axis)}
    return [term for term in TERM_KEYS if term in found]


def _ratios(rows: list[dict[str, Any]], p: dict, term: str) -> np.ndarray:
    """Fitted over true value of a term, every axis and done run of a summary entry where both are there."""
    return np.array([row[f"{term}.{k}"] / row[f"{TRUTH}.{term}.{k}"] for row in entry_rows(rows, p)
                     for k in range(AXES) if row.get(ERROR) is None and row.get(f"{term}.{k}") is not None
                     and (row.get(f"{TRUTH}.{term}.{k}") or 0.0) > 0.0], dtype=float)


def _histograms(summary: dict, rows: list[dict[str, Any]], terms: list[str], plt) -> bytes:
    columns = min(len(terms), 3)
    rows_ = -(-len(terms) // columns)
    fig, axes = plt.subplots(rows_, columns, figsize=(3.6 * columns, 3.0 * rows_ + 0.8), squeeze=False)
    for ax in axes.flat[len(terms):]:
        ax.set_visible(False)
    for ax, term in zip(axes.flat, terms):
        for p, label in zip(summary["points"], point_labels(summary["points"])):
            ratios = _ratios(rows, p, term)
            if ratios.size:
                ax.hist(ratios, bins=20, density=True, histtype="step", label=label)
        ax.axvline(1.0, color="k", linestyle="--", linewidth=0.8)
        ax.set_xlabel(f"{term} fitted / truth", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("density (x, y, z pooled)", fontsize=8)
    if len(summary["points"]) <= 8:
        fig.legend(*axes.flat[0].get_legend_handles_labels(), fontsize=7, loc="lower center", ncols=2)
    fig.suptitle("Fitted noise terms over the configured ones")
    fig.tight_layout(rect=(0.0, 0.08 if len(summary["points"]) <= 8 else 0.0, 1.0, 1.0))
    return png(fig)


def _coverage(summary: dict, term: str, plt) -> bytes:
    """The coverage of one term's intervals per sweep point and axis, over its binomial band."""
    entries = [(f"{label} {AXIS_NAMES[k]}", a) for p, label in zip(summary["points"], point_labels(summary["points"]))
               for k, a in enumerate(p.get("terms", {}).get(term, [])) if "coverage" in a]
    nominal = next(p["ci_level"] for p in summary["points"] if "ci_level" in p)
    return banded([label for label, _ in entries], [a["coverage_band"] for _, a in entries], plt,
                  f"95 % binomial band of {nominal:.1%} intervals", nominal, "coverage of the interval",
                  f"{term}: fraction of runs whose interval holds the truth",
                  [(0.0, [a["coverage"] for _, a in entries], "coverage")])


def _value(a: dict, key: str, form: str) -> str:
    return "–" if a.get(key) is None else format(a[key], form)


def _point_rows(p: dict, terms: list[str]) -> list[tuple[bool, str]]:
    """A sweep point's rows, one a term and axis; the point spans its rows, a term its axes'."""
    groups = [(term, p["terms"][term]) for term in terms if term in p.get("terms", {})]
    span = sum(len(per_axis) for _, per_axis in groups)
    rows = []
    for term, per_axis in groups:
        flagged = not all(a.get("coverage_inside", True) for a in per_axis)
        for k, a in enumerate(per_axis):
            cells = ""
            if not rows:
                cells += point_cell(p, span) + cell(p["runs"], span=span) + cell(p["failed"], span=span)
            if k == 0:
                cells += cell(breakable(term), num=False, span=len(per_axis))
            cells += cell(AXIS_NAMES[k], num=False) + "".join(
                cell(_value(a, key, form)) for key, form in (("truth", ".3g"), ("mean", ".3g"), ("std", ".2g"),
                                                             ("relative_error_mean", "+.1%"), ("unresolved", "d")))
            cells += (cell(_value(a, "coverage", ".2f"), bold=not a.get("coverage_inside", True))
                      + cell(band_text(a.get("coverage_band"), ".2f")))
            rows.append((flagged, cells))
    return rows


def _table(summary: dict, terms: list[str]) -> str:
    head = ["sweep point", "runs", "failed", "term", "axis", "truth", "mean", "std", "mean rel. error",
            "un&shy;resolved", "cover&shy;age", "band"]
    return table_html(head, [row for p in summary["points"] for row in _point_rows(p, terms)])


def noise_section(summary: dict, rows: list[dict[str, Any]], plt) -> str:
    """A noise campaign's part of the page: the table, the fitted/truth histograms, the coverage per term."""
    terms = _terms(summary)
    if not terms:
        return "<h2>Noise terms per sweep point</h2><p>No run resolved a term the config puts in.</p>"
    figures = [("Fitted over configured noise term, every sweep point", _histograms(summary, rows, terms, plt))]
    figures += [(f"{term}: coverage of the reported interval with its 95 % binomial band", _coverage(summary, term, plt))
                for term in terms]
    return (f"<h2>Noise terms per sweep point</h2>{_table(summary, terms)}"
            f"<p class='meta'>Units as in noise.json; a term is highlighted when a coverage falls outside its band, "
            "that coverage in bold.</p>"
            f"<h2>Figures</h2>{figures_html(figures)}")
