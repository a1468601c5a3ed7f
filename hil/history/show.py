"""``hil history``: the trials and each unit's run-to-run figures from the history, as a table or JSON, and
history.html (docs/history.md)."""

from __future__ import annotations

import json
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from hil.history.filing import sync_spool
from hil.history.page import write_history_page
from hil.history.repeatability import history_summary
from hil.history.location import resolve
from hil.history.store import History, HistoryError
from hil.inputs import InputError

LEFT_OUT_WORDS = {"replay": "replays of a trial", "not_completed": "not completed",
                  "not_observable": "bias not observable", "not_converged": "not converged",
                  "no_serial": "without a unit serial"}


def show_history(option: str | None, dut: str | None, since: str | None, as_json: bool, out: Path | None,
                 sync: bool = False) -> int:
    """``hil history``: the trials and each unit's figures as a table (or JSON), history.html in ``out``, the
    spooled trials filed first with ``sync``; exit code. A ``since`` that is not a date, or a history that does
    not exist or cannot be read or take the spooled trials, is an :class:`InputError`."""
    start = since_utc(since)
    history = History(resolve(option))
    try:
        if sync:
            sync_spool(history)
        trials = history.trials(dut, start)
    except HistoryError as exc:
        raise InputError(str(exc)) from None
    summary = history_summary(dut, start, trials)
    if as_json:
        print(json.dumps(summary, indent=1))
    else:
        print(_text(summary))
    if out is not None:
        print(f"history: {write_history_page(out, summary)}", file=sys.stderr if as_json else sys.stdout)
    return 0


def since_utc(text: str | None) -> str | None:
    """``--since`` (an ISO 8601 date or time, UTC unless it names its offset) as the rows write their start
    times (``2026-12-04T00:00:00+00:00``), so that they compare as text; None for None."""
    if text is None:
        return None
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        raise InputError(f"--since {text}: not an ISO 8601 date or time (2026-12-04, 2026-12-04T13:00)") from None
    when = when.replace(tzinfo=timezone.utc) if when.tzinfo is None else when.astimezone(timezone.utc)
    return when.isoformat(timespec="seconds")


def _text(summary: dict[str, Any]) -> str:
    lines = [f"{'started (UTC)':25} {'kind':11} {'unit':12} {'ended':11} {'verdict':11} name"]
    for t in summary["trials"]:
        ended = (t["ended"] or "-").split(":")[0]  # completed, early or interrupted: the reason is in the row
        kind = "replay" if t.get("replay_of") else t["kind"]
        lines.append(f"{t['started_utc'] or '':25} {kind:11} {t['dut_serial'] or '-':12} {ended:11} "
                     f"{t['verdict'] or '-':11} {t['name'] or ''}")
    return "\n".join(lines + [_unit_line(unit) for unit in summary["units"]])


def _unit_line(unit: dict[str, Any]) -> str:
    """One unit's repeatability in a line: the std over its runs per axis with its interval, the within-run
    sigma, and the swing rows left out and why."""
    name = unit["dut_serial"] or "(no serial)"
    found = unit["accel_bias_repeatability_ug"]
    if found is None:
        figures = f"{unit['runs']} run(s): the bias repeatability needs two"
    else:
        axes = ", ".join(f"{a} {s:.2f} [{lo:.2f}, {hi:.2f}]"
                         for a, s, (lo, hi) in zip("xyz", found, unit["accel_bias_repeatability_ci_ug"]))
        within = unit["accel_bias_within_run_sigma_ug"]
        sigma = "/".join(f"{w:.2f}" for w in within) if within else "-"
        figures = (f"bias repeatability over {unit['runs']} runs (ug, 95 % interval): {axes}; "
                   f"within-run sigma {sigma}")
    left = ", ".join(f"{n} {LEFT_OUT_WORDS[reason]}" for reason, n in unit["left_out"].items() if n)
    return f"{name}: {figures}; left out: {left or 'none'}"
