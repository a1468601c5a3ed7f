"""``hil history``: a unit's trials and run-to-run figures from the history, as a table or JSON, and
history.html (docs/history.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from hil.history.page import write_history_page
from hil.history.repeatability import unit_summary
from hil.history.store import History, HistoryError, resolve
from hil.inputs import InputError


def show_history(option: str | None, dut: str | None, since: str | None, as_json: bool, out: Path | None) -> int:
    """``hil history``: the unit's trials and figures as a table (or JSON), history.html in ``out``; exit code."""
    try:
        trials = History(resolve(option)).trials(dut, since)
    except HistoryError as exc:
        raise InputError(str(exc)) from None
    summary = unit_summary(dut, trials)
    if as_json:
        print(json.dumps(summary, indent=1))
    else:
        print(_text(summary))
    if out is not None:
        print(f"history: {write_history_page(out, summary)}", file=sys.stderr if as_json else sys.stdout)
    return 0


def _text(summary: dict[str, Any]) -> str:
    lines = [f"{'started (UTC)':25} {'kind':11} {'unit':12} {'ended':10} {'verdict':8} name"]
    for t in summary["trials"]:
        ended = t["ended"] if t["ended"] == "completed" else "early"
        lines.append(f"{t['started_utc'] or '':25} {t['kind']:11} {t['dut_serial'] or '-':12} {ended:10} "
                     f"{t['verdict'] or '-':8} {t['name'] or ''}")
    found = summary["accel_bias_repeatability_ug"]
    unit = summary["dut_serial"] or "every unit"
    if found is None:
        lines.append(f"{unit}: {summary['runs']} completed swing trials; the bias repeatability needs two")
    else:
        ci = summary["accel_bias_repeatability_ci_ug"]
        within = summary["accel_bias_within_run_sigma_ug"]
        lines.append(f"{unit}: accelerometer bias repeatability over {summary['runs']} runs (ug, 95 % interval; "
                     "within-run sigma):")
        lines += [f"  {a}: {s:8.2f}  [{lo:.2f}, {hi:.2f}]  {w:.2f}" for a, s, (lo, hi), w in zip("xyz", found, ci, within)]
    return "\n".join(lines)
