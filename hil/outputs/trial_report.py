"""The trial report: ``report.html`` beside result.json, readable offline, and ``junit.xml`` for CI.

The page lists the trial's measurements (:mod:`hil.outputs.measurements`). Limits come from
``output.limits`` of the trial config (the copy ``config.yaml`` in the output directory) unless given. The page is one self-contained file: the figures are
embedded as PNG data URIs, the style sheet is inline, nothing is fetched from anywhere.
"""

from __future__ import annotations

import base64
import html
import json
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hil.config import ReportLimits, load_config
from hil.outputs.calibration_section import RESIDUALS_PNG, calibration_lead
from hil.outputs.figures import FIGURES, Draw, write_figures
from hil.outputs.junit import write_junit
from hil.outputs.html_page import REPORT_NAME, ReportError, html_page, measurement_table
from hil.outputs.judgement import Judgement, judge
from hil.outputs.measurements import FAIL, NOT_JUDGED, Measurement, format_value
from hil.outputs.output_dir import NOISE_JSON
from hil.outputs.page_header import page_header
from hil.outputs.record import PROPERTIES
from hil.outputs.result import COMPLETED, calibration_applied_text
from hil.outputs.series import SERIES_COLUMNS, SERIES_NAME, read_series

_CAPTIONS = {
    "bias.png": "Accelerometer bias estimate with its ±3σ band and the truth (cf. Liu 2019 Fig. 3)",
    "observability.png": "Rank and condition number of the scaled Gram matrix (cf. Liu 2019 Fig. 2)",
    "alignment.png": "Alignment error against the turntable, methods 1 and 2 and the theoretical error "
    "(cf. Liu 2019 Fig. 4)",
    "allan.png": "Overlapping Allan deviation with its intervals, the fitted terms' slopes and read-off points",
    RESIDUALS_PNG: "Residual of each window's mean output against its reference, before and after calibration",
}


def write_report(out_dir: Path, limits: ReportLimits | None = None,
                 draw: Draw = write_figures) -> Path:
    """Write ``out_dir/report.html`` from result.json, the figures and series.csv, and junit.xml beside it
    (:mod:`hil.outputs.junit`); returns the report's path. Figures missing from ``out_dir`` are drawn from
    series.csv by ``draw`` (as :func:`~hil.outputs.figures.write_figures`).

    Without ``limits`` the limits come from ``out_dir/config.yaml`` (the trial config's copy);
    without that file nothing is judged.
    """
    return _write_report(Path(out_dir), limits, draw)[0]


def rebuild_report(out_dir: Path) -> tuple[Path, str | None]:
    """``hil report``: the report of a trial's outputs (:func:`write_report`), of a noise characterisation's
    (:func:`write_noise_report`) when the directory holds noise.json without a trial's result.json, or of a rate
    test's (:func:`~hil.outputs.ratetest.rebuild_ratetest`) when it holds the test's document without one; the
    page and the verdict (None for a noise characterisation, which has none)."""
    from hil.outputs.ratetest import ratetest_document, rebuild_ratetest  # hil report's only

    out_dir = Path(out_dir)
    document = ratetest_document(out_dir)
    if document is not None and not (out_dir / "result.json").exists():
        return rebuild_ratetest(document)
    if (out_dir / NOISE_JSON).exists() and not (out_dir / "result.json").exists():
        try:
            return write_noise_report(out_dir), None
        except (KeyError, TypeError, ValueError) as exc:  # ValueError: JSON that does not parse
            raise ReportError(f"{out_dir / NOISE_JSON}: not a noise.json this version can read ({type(exc).__name__}: "
                              f"{exc}); run hil noise again") from None
    return _write_report(out_dir)


def _write_report(out_dir: Path, limits: ReportLimits | None = None,
                  draw: Draw = write_figures) -> tuple[Path, str]:
    """:func:`write_report`; the page and the trial's verdict (:func:`~hil.outputs.judgement.judge`)."""
    result_path = out_dir / "result.json"
    try:
        result = json.loads(result_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ReportError(f"{result_path}: not found; is {out_dir} the output directory of a trial?") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ReportError(f"{result_path}: not valid JSON ({exc}); run the trial again to rewrite it") from None
    if not isinstance(result, dict):
        raise ReportError(f"{result_path}: not a trial result (a JSON object is expected)")
    from hil.outputs.result_schema import result_problem  # its models: a result.json read back, not one written

    problem = result_problem(result)
    if problem is not None:  # judged as it stands, a value of another shape could pass a limit unread
        raise ReportError(f"{result_path}: not a trial result of this version ({problem}; "
                          'docs/contracts.md, "result.json")')
    notes = []
    if limits is None:
        config = out_dir / "config.yaml"
        if config.exists():
            limits = load_config(config).limits
        else:
            limits = ReportLimits()
            notes.append("config.yaml not found beside result.json: no limits, nothing judged.")
    judged = judge(result, limits)
    return write_judged_report(out_dir, result, judged, draw, notes), judged.verdict


def write_judged_report(out_dir: Path, result: dict, judged: Judgement, draw: Draw = write_figures,
                        notes: Sequence[str] = ()) -> Path:
    """``out_dir/report.html`` and junit.xml of a result.json document (as written) and its judgement, computed
    once for both (``notes``: said under the summary); returns the report's path."""
    results = list(judged.measurements)
    notes = list(notes)
    if not any(m.outcome != NOT_JUDGED for m in results):
        notes.append("No limits are set (output.limits in the trial config): the verdict judges nothing.")
    series = read_series(out_dir / SERIES_NAME)
    page = _render(result, results, judged.verdict, _figures(out_dir, series, result, draw), series, notes,
                   _noise(out_dir))
    path = out_dir / REPORT_NAME
    path.write_text(page, encoding="utf-8")
    write_junit(out_dir, result, results)
    return path


def write_noise_report(out_dir: Path) -> Path:
    """report.html of a noise characterisation: the trial's report with its noise section when the
    directory holds a trial's result.json, else a page of the noise section and allan.png alone."""
    if (out_dir / "result.json").exists():
        return write_report(out_dir)
    from hil.outputs.noise_section import noise_section  # the Allan analysis: a noise characterisation's only

    figures = _figure_html(_figures(out_dir, None, {}))
    doc = json.loads((out_dir / NOISE_JSON).read_text())
    record = doc.get("record") or {}
    name = (doc.get("trial") or {}).get("name") or Path(record.get("source") or out_dir.name).stem
    header = page_header("Noise characterisation", name, record)
    page = html_page(header, f"{name}: noise", f"{noise_section(doc)}<h2>Figures</h2>{figures}")
    path = out_dir / REPORT_NAME
    path.write_text(page, encoding="utf-8")
    return path


def _noise(out_dir: Path) -> str:
    path = out_dir / NOISE_JSON
    if not path.exists():
        return ""
    from hil.outputs.noise_section import noise_section  # the Allan analysis: a noise characterisation's only

    return noise_section(json.loads(path.read_text(encoding="utf-8")))


# --- page ------------------------------------------------------------------------------------------


def _figures(out_dir: Path, series: dict[str, np.ndarray] | None, result: dict,
             draw: Draw = write_figures) -> list[tuple[str, bytes]]:
    """(file name, PNG bytes) of the trial's figures; drawn from series.csv when the PNGs are missing."""
    names = list(FIGURES) + sorted(p.name for p in out_dir.glob("*.png") if p.name not in FIGURES)
    if series is not None and not all((out_dir / n).exists() for n in FIGURES):
        if all(c in series for c in SERIES_COLUMNS):
            with tempfile.TemporaryDirectory() as tmp:
                draw(Path(tmp), np.column_stack([series[c] for c in SERIES_COLUMNS]), result)
                drawn = {n: (Path(tmp) / n).read_bytes() for n in FIGURES}
            return [(n, (out_dir / n).read_bytes() if (out_dir / n).exists() else drawn[n]) for n in names
                    if (out_dir / n).exists() or n in drawn]  # fmt: skip
    return [(n, (out_dir / n).read_bytes()) for n in names if (out_dir / n).exists()]


def _history(series: dict[str, np.ndarray] | None) -> str:
    """Bias and 1σ at a few instants of the trial (10 %, 25 %, 50 %, 100 %)."""
    if series is None or "bias_x_ug" not in series:
        return ""
    t = series["t_s"]
    rows = []
    for frac in (0.1, 0.25, 0.5, 1.0):
        k = min(int(np.searchsorted(t, frac * t[-1])), len(t) - 1)
        cells = "".join(
            f"<td>{format_value(float(series[f'bias_{a}_ug'][k]), float(series[f'sigma_{a}_ug'][k]))} ± "
            f"{format_value(float(series[f'sigma_{a}_ug'][k]))}</td>"
            if np.isfinite(series[f"bias_{a}_ug"][k]) else "<td>not observable</td>"
            for a in "xyz"
        )  # fmt: skip
        rows.append(f"<tr><td>{format_value(float(t[k]))}</td>{cells}</tr>")
    return (
        "<h2>Bias during the trial</h2><table class='history'><thead><tr><th>t (s)</th><th>x (µg)</th>"
        "<th>y (µg)</th><th>z (µg)</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>"
    )


def _render(result: dict, results: list[Measurement], verdict: str, figures: list[tuple[str, bytes]],
            series: dict[str, np.ndarray] | None, notes: list[str], noise: str = "") -> str:  # fmt: skip
    trial = result.get("trial", {})
    ended = result["ended"]
    if ended != COMPLETED:
        notes = [f"The trial did not complete ({ended}): its verdict is {verdict}, neither PASS nor FAIL; the "
                 "measurements are of the data received.", *notes]
    judged = [m for m in results if m.outcome != NOT_JUDGED]
    failed = [m for m in judged if m.outcome == FAIL]
    e = html.escape
    calibrated = result.get("calibration") is not None
    lead, shown, folded, estimate = "", results, [], ""
    if calibrated:  # a calibration leads with what it found; its unjudged measurements fold away
        lead = calibration_lead(result["calibration"]) + _figure_html([f for f in figures if f[0] == RESIDUALS_PNG])
        figures = [f for f in figures if f[0] != RESIDUALS_PNG]
        shown = [m for m in results if m.outcome != NOT_JUDGED]
        folded = [m for m in results if m.outcome == NOT_JUDGED]
        estimate = "<p class='meta'>The online bias estimate (Liu et al. 2019) over the calibration's motion.</p>"
    summary = (f"{len(judged)} of {len(results)} measurements judged, {len(failed)} failed"
               + (": " + ", ".join(m.name for m in failed) if failed else ""))  # fmt: skip
    what = ("Multi-position calibration (2018 three-stage paper): the terms in calibration.html"
            if calibrated else "Accelerometer bias from swinging motion (Liu et al. 2019)")
    fold = (f"<details><summary>{len(folded)} measurements not judged (no limit in output.limits)</summary>"
            f"{measurement_table(folded)}</details>" if folded else "")
    body = f"""<p class="meta">{format_value(trial.get("duration_s"))} s, {format_value(trial.get("samples"))} samples.
{e(what)}.</p>
<p class="meta">{e(calibration_applied_text(result.get("calibration_applied")))}.</p>
{_record_table(result.get("record"))}
<p>{e(summary)}.</p>
{"".join(f'<p class="note">{e(n)}</p>' for n in notes)}
{lead}
<h2>Measurements</h2>
{measurement_table(shown)}{fold}
{_history(series)}
{noise}
<h2>Figures</h2>{estimate}
{_figure_html(figures) or "<p>No figures in this directory.</p>"}
<p class="meta">Built from result.json, series.csv and the figures beside this file. The Rerun recording
(recording.rrd, when saved) opens with <code>rerun recording.rrd</code>.</p>"""
    kind = "Calibration report" if calibrated else "Trial report"
    header = page_header(kind, str(trial.get("name", "trial")), result.get("record"), ended, verdict)
    return html_page(header, f"{trial.get('name', 'trial')}: {verdict}", body)


def _record_table(record: dict | None) -> str:
    """The trial's record as a two-column table (who, which unit, where, which software, when)."""
    if not record:
        return ""
    rows = "".join(f"<tr><th>{html.escape(key)}</th><td>{html.escape(str(record[key]))}</td></tr>" for key in PROPERTIES
                   if record.get(key) is not None)
    return f'<table class="record"><tbody>{rows}</tbody></table>'



def _figure_html(figures: list[tuple[str, bytes]]) -> str:
    e = html.escape
    return "".join(
        f"<figure><img alt='{e(name)}' src='data:image/png;base64,{base64.b64encode(data).decode()}'>"
        f"<figcaption>{e(_CAPTIONS.get(name, name))}</figcaption></figure>"
        for name, data in figures
    )
