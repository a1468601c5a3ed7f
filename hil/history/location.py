"""Where the history is, without SQLAlchemy: the database ``--history`` or $HIL_HISTORY names, else the default
file; and, for a command that replaced another trial's outputs, their rows made to point nowhere in a SQLite file of
the last revision with the standard library alone (:func:`forgotten`), before anything loads :mod:`hil.history.store`
(SQLAlchemy, about 0.1 s)."""

from __future__ import annotations

import os
from pathlib import Path

ENV = "HIL_HISTORY"
HEAD = "0004"  # the last revision in migrations/versions: a database there needs no migration (and no Alembic)


def data_dir() -> Path:
    """The user's data directory for the project ($XDG_DATA_HOME, else ~/.local/share, then turntable-hil)."""
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "turntable-hil"


def default_location() -> Path:
    """history.sqlite under the user's data directory."""
    return data_dir() / "history.sqlite"


def resolve(option: str | None) -> str:
    """The database named by ``--history`` (``option``), else by $HIL_HISTORY, else the default file."""
    return option or os.environ.get(ENV) or str(default_location())


def forgotten(location: str, out_dir: str) -> bool:
    """Whether the trials of the history at ``location`` that name ``out_dir`` now point nowhere (``out_dir``
    null), as :meth:`hil.history.store.History.forget_outputs` makes them, done here when the history is a SQLite
    file (a path, not a URL) of the last revision (:data:`HEAD`), or none is there (a SQLite history not made yet
    stays so). False for any other (a URL, an older schema to migrate first) and on any error: the store opens it
    then, and words its failure."""
    if "://" in location:
        return False
    path = Path(location).expanduser()
    if not path.exists():
        return True
    import sqlite3  # the standard library's driver: one update needs no engine

    try:
        db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=rw", uri=True, timeout=0, isolation_level=None)
    except sqlite3.Error:
        return False
    try:
        db.execute("BEGIN IMMEDIATE")  # the writer's lock first, at once: a held one is the store's to wait for
        if db.execute("SELECT version_num FROM alembic_version").fetchall() != [(HEAD,)]:
            db.execute("ROLLBACK")
            return False
        db.execute("UPDATE trials SET out_dir = NULL WHERE out_dir = ?", (out_dir,))
        db.execute("COMMIT")
    except sqlite3.Error:
        return False  # rolled back as the connection closes
    finally:
        db.close()
    return True
