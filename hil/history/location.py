"""Where the history is, without SQLAlchemy: the database ``--history`` or $HIL_HISTORY names, else the default
file, and whether a SQLite history there can name a trial's output directory at all (:func:`may_name`), which a
command that replaced outputs asks before it loads :mod:`hil.history.store` (SQLAlchemy, about 0.1 s)."""

from __future__ import annotations

import os
from pathlib import Path

ENV = "HIL_HISTORY"
HEAD = "0004"  # the last revision in migrations/versions: a database there needs no migration (and no Alembic)
LOCK_TIMEOUT_S = 2.0  # how long a SQLite write waits for another writer's lock before it gives up


def data_dir() -> Path:
    """The user's data directory for the project ($XDG_DATA_HOME, else ~/.local/share, then turntable-hil)."""
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "turntable-hil"


def default_location() -> Path:
    """history.sqlite under the user's data directory."""
    return data_dir() / "history.sqlite"


def resolve(option: str | None) -> str:
    """The database named by ``--history`` (``option``), else by $HIL_HISTORY, else the default file."""
    return option or os.environ.get(ENV) or str(default_location())


def may_name(location: str, out_dir: str) -> bool:
    """False only when the history at ``location`` is a SQLite file (a path, not a URL) that is not there, or one
    of the last revision (:data:`HEAD`) whose trials name no ``out_dir``: then forgetting ``out_dir`` there changes
    nothing. True otherwise (a URL, an older schema, a file that cannot be read): the history is opened to tell."""
    if "://" in location:
        return True
    path = Path(location).expanduser()
    if not path.exists():
        return False
    import sqlite3  # the standard library's driver: a read needs no engine

    try:
        db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=LOCK_TIMEOUT_S)
    except sqlite3.Error:
        return True
    try:
        revision = db.execute("SELECT version_num FROM alembic_version").fetchall()
        named = db.execute("SELECT 1 FROM trials WHERE out_dir = ? LIMIT 1", (out_dir,)).fetchall()
    except sqlite3.Error:
        return True
    finally:
        db.close()
    return revision != [(HEAD,)] or bool(named)
