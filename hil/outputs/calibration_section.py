"""The lead of a calibration's report.html: what the trial is and what it found, before its measurements."""

from __future__ import annotations

import html

from hil.outputs.measurements import format_value

RESIDUALS_PNG = "calibration_residuals.png"


def calibration_lead(summary: dict) -> str:
    """HTML: result.json's ``calibration`` summary in a sentence and where its terms are (calibration.html)."""
    worst = summary.get("worst_error_sigma")
    nulls = len(summary.get("unobservable") or [])
    facts = [f"Over {summary.get('positions')} positions",
             f"residual after calibration {format_value(summary.get('residual_rms_ug'))} µg RMS, "
             f"{format_value(summary.get('residual_max_ug'))} µg max"]
    if worst is not None:
        facts.append(f"largest error of a term against the emulated truth {format_value(worst)}σ")
    facts.append(f"{nulls} term{'' if nulls == 1 else 's'} without an estimate (null in calibration.json, "
                 "never applied)")
    return (f"<h2>Calibration</h2><p>{html.escape('; '.join(facts))}. Every term with its 1σ, the truth and why a "
            'term has no estimate: <a href="calibration.html">calibration.html</a>.</p>')
