"""history.html: the trials in a table, each unit's bias repeatability, and every headline figure over time
(docs/history.md, "history.html")."""

from __future__ import annotations

import html
import io
from datetime import datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hil.history.entry import CALIBRATION, NOISE, SWING
from hil.history.repeatability import left_out_because
from hil.outputs.figures import pyplot
from hil.outputs.html_page import figures_html, html_page
from hil.outputs.measurements import format_value
from hil.outputs.page_header import page_header
from hil.outputs.record import source_commit
from hil import package_version

if TYPE_CHECKING:
    from matplotlib.figure import Figure

HISTORY_HTML = "history.html"
AXES = ("x", "y", "z")
COLUMNS = ("started_utc", "kind", "dut_serial", "name", "ended", "verdict", "dut_part", "operator", "station",
           "software_version")
TITLES = {SWING: "Swing trials", CALIBRATION: "Calibration terms", NOISE: "Noise terms"}
MIN_PAD = timedelta(minutes=30)  # the time axis reaches this far beyond the first and last trial at least
Series = dict[str, dict[str | None, tuple[list[datetime], list[list[float]]]]]  # figure key -> unit -> (t, values)


def write_history_page(out: Path, summary: dict[str, Any]) -> Path:
    """Writes OUT/history.html from :func:`hil.history.repeatability.history_summary`'s document."""
    out.mkdir(parents=True, exist_ok=True)
    trials = summary["trials"]
    unit = summary["dut_serial"] or "every unit"
    figures = [(title, _png(series_figure(title, series))) for title, series in trial_series(trials) if series]
    runs = ", ".join(f"{u['dut_serial'] or '(no serial)'} {u['runs']}" for u in summary["units"])
    body = (f'<p class="meta">{len(trials)} trials; runs of each unit (completed, observable, converged swing trials, '
            f"never a replay): {html.escape(runs) or 'none'}.</p>"
            f"{_repeatability(summary['units'])}<h2>Trials</h2>{_table(trials)}<h2>Over time</h2>"
            f"{figures_html(figures)}")
    path = out / HISTORY_HTML
    header = page_header("Trial history", unit, {"software_version": package_version(), "commit": source_commit()})
    path.write_text(html_page(header, f"history of {unit}", body))
    return path


def _repeatability(units: list[dict[str, Any]]) -> str:
    """The repeatability table: per unit its runs, the rows left out and why, and per axis the std over runs,
    its interval and the mean within-run sigma."""
    rows = "".join(_unit_rows(unit) for unit in units)
    return ("<h2>Accelerometer bias repeatability</h2><table class='repeatability'><thead><tr><th>unit</th>"
            "<th>runs</th><th>left out</th><th>axis</th><th>std over runs (ug)</th><th>95 % interval (ug)</th>"
            f"<th>mean within-run sigma (ug)</th></tr></thead><tbody>{rows}</tbody></table>")


def _unit_rows(unit: dict[str, Any]) -> str:
    e = html.escape
    left = ", ".join(f"{n} {reason.replace('_', ' ')}" for reason, n in unit["left_out"].items() if n) or "none"
    found = unit["accel_bias_repeatability_ug"]
    head = f"<td>{e(unit['dut_serial'] or '(no serial)')}</td><td class='num'>{unit['runs']}</td><td>{e(left)}</td>"
    if found is None:
        return f"<tr>{head}<td colspan='4'>needs two runs</td></tr>"
    within = unit["accel_bias_within_run_sigma_ug"] or [None] * 3
    cells = [f"<td>{a}</td><td class='num'>{format_value(s)}</td><td class='num'>{format_value(lo)} .. "
             f"{format_value(hi)}</td><td class='num'>{format_value(w)}</td>"
             for a, s, (lo, hi), w in zip(AXES, found, unit["accel_bias_repeatability_ci_ug"], within)]
    head = head.replace("<td", "<td rowspan='3'")
    return f"<tr>{head}{cells[0]}</tr>" + "".join(f"<tr>{c}</tr>" for c in cells[1:])


def _table(trials: list[dict[str, Any]]) -> str:
    e = html.escape
    head = "".join(f"<th>{'unit' if c == 'dut_serial' else c}</th>" for c in COLUMNS)
    rows = "".join("<tr>" + "".join(f"<td>{e(_cell(t, c))}</td>" for c in COLUMNS) + "</tr>" for t in trials)
    return f"<table class='trials'><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"


def _cell(trial: dict[str, Any], column: str) -> str:
    if column == "kind" and trial.get("replay_of"):
        return f"{trial['kind']} (replay)"
    return "" if trial.get(column) is None else str(trial[column])


def plotted(trial: dict[str, Any]) -> bool:
    """Whether ``trial``'s figures are drawn over time: a completed trial, not a replay (it repeats its trial's
    figures); a swing trial only as a run of the repeatability (observable, converged), with or without a serial."""
    if trial["kind"] == SWING:
        return left_out_because(trial) in (None, "no_serial")
    return trial["kind"] in TITLES and trial["ended"] == "completed" and not trial.get("replay_of")


def trial_series(trials: list[dict[str, Any]]) -> list[tuple[str, Series]]:
    """(figure title, {figure key: {unit: (start times, values)}}) for each kind's figures of the trials
    :func:`plotted`."""
    groups: dict[str, Series] = {title: {} for title in TITLES.values()}
    for trial in trials:
        if not plotted(trial) or not trial["started_utc"]:
            continue
        when = datetime.fromisoformat(trial["started_utc"])
        for key, value in trial["figures"].items():
            if not isinstance(value, list) or None in value or key.endswith(".sigma"):
                continue
            times, values = groups[TITLES[trial["kind"]]].setdefault(key, {}).setdefault(trial["dut_serial"], ([], []))
            times.append(when)
            values.append(value)
    return list(groups.items())


def series_figure(title: str, series: Series) -> Figure:
    """One plot per figure key over the trials' start times, one line per axis (and unit), with a legend; the time
    axis spans the trials and at least :data:`MIN_PAD` either side (one trial: an hour, not years)."""
    import matplotlib.dates as mdates  # with matplotlib, which pyplot() imports

    plt = pyplot()
    fig, axes = plt.subplots(len(series), 1, figsize=(12, 2.2 * len(series)), sharex=True, squeeze=False)
    several = len({unit for lines in series.values() for unit in lines}) > 1
    for ax, (key, lines) in zip(axes[:, 0], series.items()):
        for unit, (times, values) in lines.items():
            values = np.array(values, dtype=float)
            for column in range(values.shape[1]):
                axis = AXES[column] if values.shape[1] == 3 else str(column)
                ax.plot(times, values[:, column], "o-", label=f"{unit or '(no serial)'} {axis}" if several else axis)
        ax.set_ylabel(key, fontsize=7)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.0, 0.5))
    times = [t for lines in series.values() for ts, _ in lines.values() for t in ts]
    pad = max((max(times) - min(times)) * 0.05, MIN_PAD)
    bottom = axes[-1, 0]
    bottom.set_xlim(min(times) - pad, max(times) + pad)
    locator = mdates.AutoDateLocator()
    bottom.xaxis.set_major_locator(locator)
    bottom.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    bottom.set_xlabel("trial start (UTC)")
    axes[0, 0].set_title(title)
    return fig


def _png(fig: Figure) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80, bbox_inches="tight")
    pyplot().close(fig)
    return buffer.getvalue()
