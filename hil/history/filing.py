"""Filing a finished trial in the history, after its own files are written: a history that cannot be written
costs one warning line, never the trial's outputs or its exit code, and the row waits in the spool
(:mod:`hil.history.spool`) for the next trial or ``hil history --sync``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from hil.history.spool import file_spooled, keep
from hil.history.location import resolve
from hil.history.store import History, HistoryError


def file_trial(option: str | None, row: dict[str, Any]) -> None:
    """Append ``row`` to the history ``option`` names (:func:`~hil.history.location.resolve`), then the rows
    spooled for it; a failure is one warning line on stderr, the row kept in the spool."""
    history = History(resolve(option))
    try:
        history.append(row)
    except HistoryError as exc:
        print(f"hil: warning: trial not filed in the history: {exc}{_kept(history, row, exc)}", file=sys.stderr)
        return
    try:
        sync_spool(history)
    except HistoryError as exc:
        print(f"hil: warning: trials in the spool not filed in the history: {exc}", file=sys.stderr)


def sync_spool(history: History) -> int:
    """Files the rows spooled for ``history``, saying how many in one line on stderr when there were some; how
    many (a :class:`HistoryError` when it cannot, the rest left in the spool)."""
    filed = file_spooled(history)
    if filed:
        print(f"hil: {filed} trial(s) from the spool filed in the history {history.shown}", file=sys.stderr)
    return filed


def _kept(history: History, row: dict[str, Any], exc: HistoryError) -> str:
    """Keeps ``row`` in the spool unless the history cannot be there (``exc.lasting``): what the warning adds."""
    if exc.lasting:
        return ""
    try:
        path = keep(history, row)
    except OSError as error:
        return f"; not kept in the spool either: {error.filename}: {error.strerror}"
    return f"; kept in the spool {path.parent}, filed by the next trial or hil history --sync"


def forget_outputs(option: str | None, out: Path) -> None:
    """The trials of the history ``option`` names whose outputs were in ``out`` point nowhere: another trial's
    replaced them (``--overwrite``); a failure is one warning line on stderr."""
    try:
        History(resolve(option)).forget_outputs(str(out.resolve()))
    except HistoryError as exc:
        print(f"hil: warning: the history may still name {out} for the trial replaced there: {exc}", file=sys.stderr)
