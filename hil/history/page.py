"""history.html: a unit's trials in a table, its bias repeatability, and every headline figure over time
(docs/history.md, "history.html")."""

from __future__ import annotations

import html
import io
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from hil.history.entry import CALIBRATION, NOISE, SWING
from hil.outputs.figures import pyplot
from hil.outputs.measurements import format_value
from hil.outputs.page_header import page_header
from hil.outputs.record import source_commit
from hil.outputs.trial_report import figures_html, html_page
from hil.recording.recorder import package_version

HISTORY_HTML = "history.html"
AXES = ("x", "y", "z")
COLUMNS = ("started_utc", "kind", "name", "ended", "verdict", "dut_part", "operator", "station", "software_version")


def write_history_page(out: Path, summary: dict[str, Any]) -> Path:
    """Writes OUT/history.html from :func:`hil.history.repeatability.unit_summary`'s document."""
    out.mkdir(parents=True, exist_ok=True)
    trials = summary["trials"]
    unit = summary["dut_serial"] or "every unit"
    figures = [(title, _plot(title, series)) for title, series in _series(trials) if series]
    body = (f'<p class="meta">{len(trials)} trials, {summary["runs"]} completed swing trials.</p>'
            f"{_repeatability(summary)}<h2>Trials</h2>{_table(trials)}<h2>Over time</h2>{figures_html(figures)}")
    path = out / HISTORY_HTML
    header = page_header("Trial history", unit, {"software_version": package_version(), "commit": source_commit()})
    path.write_text(html_page(header, f"history of {unit}", body))
    return path


def _repeatability(summary: dict[str, Any]) -> str:
    found = summary["accel_bias_repeatability_ug"]
    if found is None:
        return "<p>Bias repeatability: needs two completed swing trials.</p>"
    ci = summary["accel_bias_repeatability_ci_ug"]
    within = summary["accel_bias_within_run_sigma_ug"] or [None] * 3
    rows = "".join(f"<tr><td>{a}</td><td class='num'>{format_value(s)}</td><td class='num'>{format_value(lo)} .. "
                   f"{format_value(hi)}</td><td class='num'>{format_value(w)}</td></tr>"
                   for a, s, (lo, hi), w in zip(AXES, found, ci, within))
    return ("<h2>Accelerometer bias repeatability</h2><table class='repeatability'><thead><tr><th>axis</th>"
            "<th>std over runs (ug)</th><th>95 % interval (ug)</th><th>mean within-run sigma (ug)</th></tr></thead>"
            f"<tbody>{rows}</tbody></table>")


def _table(trials: list[dict[str, Any]]) -> str:
    e = html.escape
    head = "".join(f"<th>{c}</th>" for c in COLUMNS)
    rows = "".join("<tr>" + "".join(f"<td>{e(str(t.get(c) if t.get(c) is not None else ''))}</td>" for c in COLUMNS)
                   + "</tr>" for t in trials)
    return f"<table class='trials'><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"


def _series(trials: list[dict[str, Any]]) -> list[tuple[str, dict[str, tuple[list, list]]]]:
    """(figure title, {label: (times, per-axis values)}) for each kind's figures present in the trials."""
    groups: dict[str, dict[str, tuple[list, list]]] = {}
    titles = {SWING: "Swing trials", CALIBRATION: "Calibration terms", NOISE: "Noise terms"}
    for trial in trials:
        if trial["ended"] != "completed" or trial["kind"] not in titles:
            continue
        when = datetime.fromisoformat(trial["started_utc"]) if trial["started_utc"] else None
        for key, value in trial["figures"].items():
            if when is None or not isinstance(value, list) or None in value or key.endswith(".sigma"):
                continue
            times, values = groups.setdefault(titles[trial["kind"]], {}).setdefault(key, ([], []))
            times.append(when)
            values.append(value)
    return [(title, groups.get(title, {})) for title in titles.values()]


def _plot(title: str, series: dict[str, tuple[list, list]]) -> bytes:
    plt = pyplot()
    fig, axes = plt.subplots(len(series), 1, figsize=(12, 2.2 * len(series)), sharex=True, squeeze=False)
    for ax, (key, (times, values)) in zip(axes[:, 0], series.items()):
        values = np.array(values, dtype=float)
        for column in range(values.shape[1]):
            ax.plot(times, values[:, column], "o-", label=AXES[column] if values.shape[1] == 3 else str(column))
        ax.set_ylabel(key, fontsize=7)
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_title(title)
    fig.autofmt_xdate()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80, bbox_inches="tight")
    plt.close(fig)
    return buffer.getvalue()
