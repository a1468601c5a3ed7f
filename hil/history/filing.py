"""Filing a finished trial in the history, after its own files are written: a history that cannot be written
costs one warning line, never the trial's outputs or its exit code."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from hil.history.store import History, HistoryError, resolve


def file_trial(option: str | None, row: dict[str, Any]) -> None:
    """Append ``row`` to the history ``option`` names (:func:`~hil.history.store.resolve`); a failure is one
    warning line on stderr."""
    try:
        History(resolve(option)).append(row)
    except HistoryError as exc:
        print(f"hil: warning: trial not filed in the history: {exc}", file=sys.stderr)


def forget_outputs(option: str | None, out: Path) -> None:
    """The trials of the history ``option`` names whose outputs were in ``out`` point nowhere: another trial's
    replaced them (``--overwrite``); a failure is one warning line on stderr."""
    try:
        History(resolve(option)).forget_outputs(str(out.resolve()))
    except HistoryError as exc:
        print(f"hil: warning: the history may still name {out} for the trial replaced there: {exc}", file=sys.stderr)
