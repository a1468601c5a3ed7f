"""``OUT/campaign.html``: one self-contained page (figures as PNG data URIs, inline style, nothing fetched),
in the style of the trial report, with the section of the campaign's kind. A swing campaign's: the consistency
table per sweep point and four figures: the normalised errors against N(0, 1), the ratio std(error)/mean(sigma)
with its band, the mean NEES with its chi-square band, the convergence time against the swept value. The
figure and table helpers here serve every kind's section. matplotlib is imported when the page is drawn."""

from __future__ import annotations

import html
import io
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hil.campaign.entries import entry_label, entry_rows, entry_values
from hil.campaign.swing_summary import SIGMA, bias_error
from hil.outputs.page_header import page_header
from hil.outputs.figures import pyplot
from hil.outputs.html_page import figures_html, html_page

REPORT_NAME = "campaign.html"
AXES = "xyz"


def point_labels(points: list[dict]) -> list[str]:
    """Short labels of the summary's entries for the figures: the keys that vary across them (a units campaign's
    unit among them), by their last part."""
    values = [entry_values(p) for p in points]
    varying = [k for k in values[0] if len({repr(v[k]) for v in values}) > 1] if values else []
    return [", ".join(f"{k.rsplit('.', 1)[-1]}={v[k]}" for k in varying) or "all runs" for v in values]


def png(fig) -> bytes:
    import matplotlib.pyplot as plt  # pyplot() of hil.outputs.figures has chosen the backend

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    return buffer.getvalue()


def _normalised(rows: list[dict[str, Any]], p: dict) -> np.ndarray:
    """(M, 3) errors over reported sigma of the runs with an estimate of a summary entry ``p``."""
    found = [(e, [row[f"{SIGMA}.{i}"] for i in range(3)]) for row in entry_rows(rows, p)
             if (e := bias_error(row)) is not None]
    if not found:
        return np.empty((0, 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.array([e for e, _ in found]) / np.array([s for _, s in found], dtype=float)


def normal_histograms(panels: list[tuple[str, list[np.ndarray]]], labels: list[str], plt, title: str) -> bytes:
    """Histograms of normalised errors (error over reported sigma) against N(0, 1): per panel (x label, one
    array a sweep point, labelled by ``labels``), non-finite values left out."""
    fig, axes = plt.subplots(1, len(panels), figsize=(10, 3.4), sharey=True, squeeze=False)
    grid = np.linspace(-4.0, 4.0, 161)
    for ax, (xlabel, per_point) in zip(axes[0], panels):
        for z, label in zip(per_point, labels):
            z = z[np.isfinite(z)]
            if z.size:
                ax.hist(z, bins=np.linspace(-4.0, 4.0, 25), density=True, histtype="step", label=label)
        ax.plot(grid, np.exp(-grid**2 / 2) / np.sqrt(2 * np.pi), "k--", label="N(0, 1)")
        ax.set_xlabel(xlabel)
    axes[0, 0].set_ylabel("density")
    if len(labels) <= 8:
        axes[0, -1].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return png(fig)


def _histograms(summary: dict, rows: list[dict[str, Any]], plt) -> bytes:
    normalised = [_normalised(rows, p) for p in summary["points"]]
    return normal_histograms([(f"error {AXES[k]} / reported sigma", [z[:, k] for z in normalised]) for k in range(3)],
                             point_labels(summary["points"]), plt, "Bias error against the reported sigma")


def banded(labels: list[str], bands: list, plt, band_label: str, ideal: float, ylabel: str, title: str, series):
    """A statistic per entry (a sweep point) over its 95 % band (``bands``, one (low, high) an entry): ``series``
    gives (x offset, values, label) per line."""
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(10, 3.6))
    for i, band in enumerate(bands):
        ax.fill_between([i - 0.4, i + 0.4], *band, color="tab:green", alpha=0.2, label=band_label if i == 0 else None)
    for offset, values, label in series:
        ax.plot(x + offset, values, "o", label=label)
    ax.axhline(ideal, color="k", linewidth=0.5)
    ax.set_xticks(x, labels, rotation=20, ha="right", fontsize=7)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return png(fig)


def _ratios(summary: dict, plt) -> bytes:
    points = [p for p in summary["points"] if "ratio" in p]
    series = [((k - 1) * 0.15, [p["ratio"][k] for p in points], f"axis {AXES[k]}") for k in range(3)]
    return banded(point_labels(points), [p["ratio_band"] for p in points], plt, "95 % band of a consistent estimator", 1.0, "std(error) / mean(sigma)",
                   "Consistency ratio per axis and sweep point", series)


def _nees(summary: dict, plt) -> bytes:
    points = [p for p in summary["points"] if "nees_mean" in p]
    return banded(point_labels(points), [p["nees_band"] for p in points], plt, "95 % chi-square band (3 dof)", 3.0, "mean NEES",
                   "Normalised estimation error squared, mean over the runs",
                   [(0.0, [p["nees_mean"] for p in points], "mean NEES")])


def _numeric_key(points: list[dict]) -> str | None:
    """The first swept key whose values are all numbers: the abscissa of the convergence figure."""
    for key in points[0]["values"] if points else ():
        if all(isinstance(p["values"][key], (int, float)) and not isinstance(p["values"][key], bool) for p in points):
            return key
    return None


def _convergence(summary: dict, plt) -> bytes | None:
    points = summary["points"]
    key = _numeric_key(points)
    if key is None:
        return None
    groups: dict[str, list[dict]] = {}
    others = point_labels([{"values": {k: v for k, v in entry_values(p).items() if k != key}} for p in points])
    for p, label in zip(points, others):
        groups.setdefault(label, []).append(p)
    fig, ax = plt.subplots(figsize=(7, 4))
    drawn = False
    for label, members in groups.items():
        members = sorted((p for p in members if p["converged_at_s"]["q50"] is not None), key=lambda p: p["values"][key])
        if not members:
            continue
        x = np.array([p["values"][key] for p in members], dtype=float)
        q = np.array([[p["converged_at_s"][n] for n in ("q05", "q50", "q95")] for p in members])
        ax.errorbar(x, q[:, 1], yerr=[q[:, 1] - q[:, 0], q[:, 2] - q[:, 1]], marker="o", capsize=3, label=label)
        drawn = True
    if not drawn:
        ax.text(0.5, 0.5, "no run converged", transform=ax.transAxes, ha="center")
    ax.set_xlabel(key)
    ax.set_ylabel("bias convergence time (s): median, 5-95 %")
    if drawn:
        ax.legend(fontsize=7)
    fig.suptitle("Convergence time against the swept value")
    fig.tight_layout()
    return png(fig)


def _num(v: Any) -> str:
    return "–" if v is None else f"{v:.3g}" if isinstance(v, float) else str(v)


def cell(content: Any, *, num: bool = True, span: int = 1, bold: bool = False) -> str:
    """A ``<td>`` of a campaign table: a number right-aligned, ``span`` rows high, in bold (a statistic outside
    its band)."""
    text = f"<strong>{content}</strong>" if bold else str(content)
    return f"<td{' class=num' if num else ''}{f' rowspan={span}' if span > 1 else ''}>{text}</td>"


def breakable(key: str) -> str:
    """A dotted key (escaped) free to break after each dot that ends a name and after each underscore."""
    return re.sub(r"\.(?=[A-Za-z_])|_", lambda m: m.group() + "<wbr>", html.escape(key))


def point_cell(p: dict, span: int = 1) -> str:
    """The cell of the summary's entry ``p``: its sweep point (and unit)."""
    return cell(breakable(entry_label(p)), num=False, span=span)


def band_text(band: list[float] | None, form: str = ".3f") -> str:
    """A band's ends, one a line."""
    return "–" if band is None else f"{band[0]:{form}} to<br>{band[1]:{form}}"


def table_html(head: list[str], rows: list[tuple[bool, str]]) -> str:
    """A campaign table: its header, and its rows (highlighted, their cells); rows of an axis each and bands on
    two lines keep every column in sight in a 1400 px window."""
    body = "".join(f"<tr{' class=row-FAIL' if flagged else ''}>{cells}</tr>" for flagged, cells in rows)
    header = "".join(f"<th>{h}</th>" for h in head)
    return f"<div class='wide'><table><thead><tr>{header}</tr></thead><tbody>{body}</tbody></table></div>"


def _point_rows(p: dict) -> list[tuple[bool, str]]:
    """A sweep point's rows, one an axis; what holds for the whole point spans them."""
    ratio_inside = p.get("ratio_inside", [True] * 3)
    nees_inside = p.get("nees_inside", True)
    flagged = not (nees_inside and all(ratio_inside))
    rows = []
    for k, axis in enumerate(AXES):
        cells = ""
        if k == 0:
            cells += point_cell(p, 3) + cell(p["runs"], span=3) + cell(p["failed"], span=3)
        cells += cell(axis, num=False)
        cells += "".join(cell(_num(p[key][k]) if key in p else "–") for key in ("error_mean_ug", "error_std_ug",
                                                                                   "sigma_mean_ug"))
        cells += cell(_num(p["ratio"][k]) if "ratio" in p else "–", bold=not ratio_inside[k])
        if k == 0:
            conv = "<br>".join(_num(p["converged_at_s"][n]) for n in ("q05", "q50", "q95"))  # beside x, y, z
            cells += (cell(band_text(p.get("ratio_band")), span=3)
                      + cell(_num(p.get("nees_mean")), span=3, bold=not nees_inside)
                      + cell(band_text(p.get("nees_band")), span=3) + cell(conv, span=3))
        rows.append((flagged, cells))
    return rows


def _table(summary: dict) -> str:
    head = ["sweep point", "runs", "failed", "axis", "error mean (µg)", "error std (µg)", "mean σ (µg)", "std/σ",
            "std/σ band", "mean NEES", "NEES band", "converged (s) 5/50/95 %"]
    return table_html(head, [row for p in summary["points"] for row in _point_rows(p)])


def swing_section(summary: dict, rows: list[dict[str, Any]], plt) -> str:
    """A swing campaign's part of the page: the consistency table and its four figures."""
    figures = [("Bias error over its reported sigma, every sweep point, against N(0, 1)", _histograms(summary, rows, plt)),
               ("std(error)/mean(sigma) per axis with the 95 % band of a consistent estimator", _ratios(summary, plt)),
               ("Mean NEES with its 95 % chi-square band", _nees(summary, plt)),
               ("Convergence time against the swept value", _convergence(summary, plt))]
    return (f"<h2>Consistency per sweep point</h2><p class='meta'>The statistic outside its band is in bold.</p>"
            f"{_table(summary)}<h2>Figures</h2>{figures_html(figures)}")


def write_campaign_report(out: Path, summary: dict, rows: list[dict[str, Any]],
                          section: Callable[[dict, list[dict[str, Any]], Any], str] = swing_section) -> Path:
    """Write ``out/campaign.html`` from the summary and the rows, with the ``section`` of the campaign's kind;
    returns its path."""
    plt = pyplot()

    cluster = summary["cluster"]
    body = (f"<p class='meta'>{summary['runs']} runs, {summary['failed']} failed, on {html.escape(cluster['scheduler'])} "
            f"with {cluster['workers']} workers. A row is highlighted when a statistic falls outside its band.</p>"
            + section(summary, rows, plt))
    path = out / REPORT_NAME
    record = summary.get("record") or {}
    name = Path(record.get("spec_path") or out.name).stem
    path.write_text(html_page(page_header("Campaign", name, record), f"{name}: campaign", body), encoding="utf-8")
    return path
