"""The spool: a trial's row that its history could not take (a server down or refusing, a file locked) is kept
as a file under the user's data directory, and filed by the next trial filed in that history or by
``hil history --sync`` (docs/history.md, "The spool"). A spooled row names its history without the password."""

from __future__ import annotations

import json
import os
import socket
import uuid
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from hil.history.location import data_dir
from hil.history.store import History

_HOST = socket.gethostname().replace(".", "_").replace("-", "_")  # a claim's name: STEM.HOST-PID.claim


def spool_dir() -> Path:
    return data_dir() / "spool"


def keep(history: History, row: dict[str, Any]) -> Path:
    """Writes ``row`` to the spool for ``history`` (whole or not at all); its path."""
    directory = spool_dir()
    directory.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S")
    path = directory / f"{stamp}-{uuid.uuid4().hex}.json"
    part = path.with_suffix(".part")
    part.write_text(json.dumps({"history": history.key, "row": row}))
    part.replace(path)
    return path


def file_spooled(history: History) -> int:
    """Files the rows spooled for ``history``, oldest first, each removed once filed; how many. Each
    is claimed first (renamed), so that two processes never file one twice; a failure puts the rest back and
    raises the :class:`~hil.history.store.HistoryError`."""
    claimed = _claim(history.key)
    filed = 0
    try:
        for path, claim, row in claimed:
            history.append(row)
            claim.unlink()
            filed += 1
    finally:
        for path, claim, _ in claimed[filed:]:
            claim.replace(path)
    return filed


def _spooled(key: str | None):
    """(path, row) of each row spooled for the history ``key``, oldest first."""
    for path in sorted(spool_dir().glob("*.json")) if key is not None else ():
        try:
            doc = json.loads(path.read_text())
        except FileNotFoundError:  # filed by another process meanwhile
            continue
        if doc.get("history") == key:
            yield path, doc["row"]


def _claim(key: str | None) -> list[tuple[Path, Path, dict[str, Any]]]:
    """The rows spooled for ``key``, each renamed to a claim of this process: (path, claim, row)."""
    _orphans_back()
    claimed = []
    for path, row in _spooled(key):
        claim = path.with_suffix(f".{_HOST}-{os.getpid()}.claim")
        try:
            path.rename(claim)
        except FileNotFoundError:  # claimed by another process
            continue
        claimed.append((path, claim, row))
    return claimed


def _orphans_back() -> None:
    """The claims of this host's processes that are no longer running (killed while filing) go back to the
    spool."""
    for claim in spool_dir().glob(f"*.{_HOST}-*.claim"):
        if not _running(int(claim.suffixes[-2].rpartition("-")[2])):
            claim.replace(claim.with_suffix("").with_suffix(".json"))


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        return True
    return True
