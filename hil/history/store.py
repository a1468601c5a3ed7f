"""The history database: SQLite through the standard library by default, any SQLAlchemy URL otherwise
(docs/history.md). The schema is versioned; opening a database brings it to :data:`MIGRATIONS`' last version."""

from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ENV = "HIL_HISTORY"
LOCK_TIMEOUT_S = 2.0  # how long a write waits for another writer's lock before it gives up
COLUMNS = ("kind", "name", "ended", "verdict", "out_dir", "dut_part", "dut_serial", "station", "operator", "notes",
           "software_version", "git_commit", "config_sha256", "started_utc", "ended_utc", "host", "figures",
           "replay_of")
# version k + 1 is reached by the statements MIGRATIONS[k]; never edit a released step, append one
MIGRATIONS: tuple[tuple[str, ...], ...] = (
    ("CREATE TABLE trials (id INTEGER PRIMARY KEY, kind TEXT NOT NULL, name TEXT, ended TEXT, verdict TEXT, "
     "out_dir TEXT, dut_part TEXT, dut_serial TEXT, station TEXT, operator TEXT, software_version TEXT, "
     "git_commit TEXT, config_sha256 TEXT, started_utc TEXT, ended_utc TEXT, host TEXT, figures TEXT NOT NULL)",),
    ("ALTER TABLE trials ADD COLUMN notes TEXT",
     "CREATE INDEX trials_by_unit ON trials (dut_serial, started_utc)"),
    # a replay names the run directory of the trial it re-processed; a trial that did not complete is never
    # PASS or FAIL (rows filed before either rule are brought to it)
    ("ALTER TABLE trials ADD COLUMN replay_of TEXT",
     "UPDATE trials SET verdict = CASE WHEN ended LIKE 'interrupted%' THEN 'INTERRUPTED' ELSE 'ENDED EARLY' END "
     "WHERE ended <> 'completed' AND verdict IN ('PASS', 'FAIL')"),
)


class HistoryError(Exception):
    """The history database cannot be opened, read or written; the message names it and why."""


def default_location() -> Path:
    """history.sqlite under the user's data directory ($XDG_DATA_HOME, else ~/.local/share)."""
    base = os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share"
    return Path(base) / "turntable-hil" / "history.sqlite"


def resolve(option: str | None) -> str:
    """The database named by ``--history`` (``option``), else by $HIL_HISTORY, else the default file."""
    return option or os.environ.get(ENV) or str(default_location())


class History:
    """One history database: ``append`` a trial's row, read ``trials``. A file path or ``sqlite:///PATH``
    opens with :mod:`sqlite3`; any other URL with SQLAlchemy (``pip install 'turntable-hil[history]'``)."""

    def __init__(self, location: str) -> None:
        self.location = location

    def append(self, row: dict[str, Any]) -> None:
        """Add one trial (``row``: :data:`COLUMNS`, ``figures`` a JSON-able dict); a SQLite file is created, in
        a directory that exists (the default location's directory is made)."""
        values = {key: row.get(key) for key in COLUMNS}
        values["figures"] = json.dumps(row.get("figures") or {})
        names = ", ".join(COLUMNS)
        with self._connection(create=True) as run:
            run(f"INSERT INTO trials ({names}) VALUES ({', '.join(':' + c for c in COLUMNS)})", values)

    def forget_outputs(self, out_dir: str) -> int:
        """The trials whose outputs were in ``out_dir``, which another trial's have replaced, point nowhere
        (``out_dir`` null); how many. A SQLite history not made yet stays so."""
        path = self._sqlite_path()
        if path is not None and not path.exists():
            return 0
        with self._connection() as run:
            rows = run("SELECT id FROM trials WHERE out_dir = :out", {"out": out_dir})
            run("UPDATE trials SET out_dir = NULL WHERE out_dir = :out", {"out": out_dir})
        return len(rows)

    def trials(self, dut_serial: str | None = None, since: str | None = None) -> list[dict[str, Any]]:
        """The trials (of the unit ``dut_serial``, started at or after ``since``, an ISO time in UTC as the
        rows hold it), oldest first; a SQLite file that does not exist is a :class:`HistoryError`."""
        where, params = [], {}
        if dut_serial is not None:
            where.append("dut_serial = :dut")
            params["dut"] = dut_serial
        if since is not None:
            where.append("started_utc >= :since")
            params["since"] = since
        clause = f" WHERE {' AND '.join(where)}" if where else ""
        with self._connection() as run:
            rows = run(f"SELECT * FROM trials{clause} ORDER BY started_utc, id", params)
        return [{**row, "figures": json.loads(row["figures"])} for row in rows]

    def version(self) -> int:
        """The schema version of the database (migrated on opening)."""
        with self._connection() as run:
            return run("SELECT version FROM schema_version", {})[0]["version"]

    @contextmanager
    def _connection(self, create: bool = False) -> Iterator:
        """A function running one SQL statement with named parameters (rows as dicts), in one transaction,
        the schema migrated first; a SQLite file that does not exist is made only to ``create`` it."""
        path = self._sqlite_path()
        if path is not None:
            self._check_file(path, create)
        try:
            with (_sqlite(path) if path is not None else _sqlalchemy(self.location)) as run:
                _migrate(run)
                yield run
        except HistoryError:
            raise
        except Exception as exc:  # the drivers' errors have no common base: any of them names the cause
            raise HistoryError(f"{self.location}: {' '.join(str(exc).split()) or type(exc).__name__}") from None

    def _check_file(self, path: Path, create: bool) -> None:
        """Refuses a SQLite file that is not there to read, or whose directory is not there to create it in
        (a mistyped path files nowhere new); makes the default location's directory."""
        if path.exists():
            return
        if not create:
            raise HistoryError(f"{self.location}: no trial history there (no such file; trials are filed there "
                               "as they run, or --history names another)")
        if path == default_location():
            path.parent.mkdir(parents=True, exist_ok=True)
        elif not path.parent.is_dir():
            raise HistoryError(f"{self.location}: no such directory {path.parent}")

    def _sqlite_path(self) -> Path | None:
        if "://" not in self.location:
            return Path(self.location).expanduser()
        if self.location.startswith("sqlite:///"):
            return Path(self.location.removeprefix("sqlite:///")).expanduser()
        return None


def _migrate(run) -> None:
    run("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)", {})
    rows = run("SELECT version FROM schema_version", {})
    if not rows:
        run("INSERT INTO schema_version (version) VALUES (0)", {})
    version = rows[0]["version"] if rows else 0
    if version > len(MIGRATIONS):
        raise HistoryError(f"schema version {version} is newer than this software's {len(MIGRATIONS)}")
    for statements in MIGRATIONS[version:]:
        for statement in statements:
            run(statement, {})
    if version < len(MIGRATIONS):
        run("UPDATE schema_version SET version = :v", {"v": len(MIGRATIONS)})


@contextmanager
def _sqlite(path: Path) -> Iterator:
    connection = sqlite3.connect(path, timeout=LOCK_TIMEOUT_S)
    connection.row_factory = sqlite3.Row
    try:
        with connection:  # one transaction: committed on success, rolled back on an error
            yield lambda sql, params: [dict(row) for row in connection.execute(sql, params).fetchall()]
    finally:
        connection.close()


@contextmanager
def _sqlalchemy(url: str) -> Iterator:
    try:
        import sqlalchemy  # an optional extra, for a database URL only
    except ImportError:
        raise HistoryError(f"{url}: a database URL needs SQLAlchemy: pip install 'turntable-hil[history]'") from None
    engine = sqlalchemy.create_engine(url)
    try:
        with engine.begin() as connection:

            def run(sql: str, params: dict) -> list[dict]:
                result = connection.execute(sqlalchemy.text(sql), params)
                return [dict(row) for row in result.mappings()] if result.returns_rows else []

            yield run
    finally:
        engine.dispose()
