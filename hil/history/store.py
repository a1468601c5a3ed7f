"""The history database through SQLAlchemy: a SQLite file by default, any SQLAlchemy URL otherwise
(docs/history.md). Its schema is :mod:`hil.history.tables`; opening a database brings it to the last of the
Alembic revisions in ``hil/history/migrations``. Every message names the database with its password hidden
(:func:`shown`), the operation and the driver's own cause, never a statement or its parameters."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import sqlalchemy as sa  # a dependency: SQLite needs nothing more, a server its driver ([history] extra)
from sqlalchemy.engine import URL, Connection, Engine
from sqlalchemy.exc import ArgumentError

from hil.history.location import HEAD, default_location
from hil.history.tables import COLUMNS, trials

LOCK_TIMEOUT_S = 2.0  # how long a SQLite write waits for another writer's lock before it gives up
CONNECT_TIMEOUT_S = 10  # how long a PostgreSQL connection waits for a server that does not answer
MIGRATIONS = Path(__file__).with_name("migrations")
LEGACY_REVISIONS = {1: "0001", 2: "0002", 3: "0003"}  # schema_version of the files versions 1-3 wrote by hand
MIGRATION_LOCK = 7_305_050  # the PostgreSQL advisory lock that keeps two stations from migrating at once
_PASSWORD_IN_URL = re.compile(r"(://[^:/@\s]*:)[^@\s]*@")
_PASSWORD_IN_DSN = re.compile(r"(password\s*=\s*)\S+", re.IGNORECASE)
_STATEMENT = re.compile(r"\s*(\[SQL:|\[parameters:|DETAIL:|\(Background on this error).*", re.DOTALL)


class NewerSchema(Exception):
    """The database's schema is of a revision this software does not know: a newer one."""


class HistoryError(Exception):
    """The history database cannot be opened, migrated, read or written; the message names it (password hidden),
    the operation and the cause. ``lasting``: another attempt cannot succeed (the database cannot be there)."""

    def __init__(self, message: str, lasting: bool = False) -> None:
        super().__init__(message)
        self.lasting = lasting


def shown(location: str) -> str:
    """``location`` as every message shows it: a URL's password replaced by ``***``."""
    try:
        return sa.make_url(location).render_as_string(hide_password=True)
    except ArgumentError:  # not a URL (a path), or one SQLAlchemy cannot read
        return _PASSWORD_IN_URL.sub(r"\1***@", location)


def _url(location: str) -> URL | None:
    """The SQLAlchemy URL of ``location`` (a path is a SQLite file's), None when it is not one."""
    if "://" not in location:
        return URL.create("sqlite", database=str(Path(location).expanduser()))
    try:
        return sa.make_url(location)
    except ArgumentError:
        return None


def _key(url: URL) -> str:
    """``url`` without its password, as the spool names a history."""
    return URL.create(url.drivername, url.username, None, url.host, url.port, url.database,
                      url.query).render_as_string(hide_password=False)


class History:
    """One history database: ``append`` trials' rows, read ``trials``. ``key``: the database named without its
    password (None for a location that is no URL), as the spool names it."""

    def __init__(self, location: str) -> None:
        self.location = location
        self.shown = shown(location)
        self.url = _url(location)
        path = self._sqlite_path()
        self.key = None if self.url is None else _key(self.url if path is None else URL.create(
            "sqlite", database=str(path.resolve())))

    def append(self, row: dict[str, Any]) -> None:
        """Add one trial (``row``: :data:`~hil.history.tables.COLUMNS`, ``figures`` a JSON-able dict) in one
        transaction; a SQLite file is created, in a directory that exists (the default location's is made)."""
        values = {key: row.get(key) for key in COLUMNS}
        values["figures"] = json.dumps(row.get("figures") or {})
        with self._connection("file", write=True, create=True) as connection:
            connection.execute(trials.insert(), values)

    def forget_outputs(self, out_dir: str) -> int:
        """The trials whose outputs were in ``out_dir``, which another trial's have replaced, point nowhere
        (``out_dir`` null); how many. A SQLite history not made yet stays so."""
        path = self._sqlite_path()
        if path is not None and not path.exists():
            return 0
        with self._connection("file", write=True) as connection:
            done = connection.execute(trials.update().where(trials.c.out_dir == out_dir).values(out_dir=None))
        return done.rowcount

    def trials(self, dut_serial: str | None = None, since: str | None = None) -> list[dict[str, Any]]:
        """The trials (of the unit ``dut_serial``, started at or after ``since``, an ISO time in UTC as the
        rows hold it), oldest first; a SQLite file that does not exist is a :class:`HistoryError`."""
        query = sa.select(trials).order_by(trials.c.started_utc, trials.c.id)
        if dut_serial is not None:
            query = query.where(trials.c.dut_serial == dut_serial)
        if since is not None:
            query = query.where(trials.c.started_utc >= since)
        with self._connection("read") as connection:
            rows = connection.execute(query).mappings().all()
        return [{**row, "figures": json.loads(row["figures"])} for row in rows]

    def version(self) -> int:
        """The schema version of the database (migrated on opening): its Alembic revision's number."""
        with self._connection("read") as connection:
            return int(_revision(connection))

    @contextmanager
    def _connection(self, operation: str, write: bool = False, create: bool = False) -> Iterator[Connection]:
        """A connection in one transaction for ``operation`` (committed when the block ends, rolled back on an
        error), the schema migrated first; a SQLite file that does not exist is made only to ``create`` it."""
        if self.url is None:
            raise HistoryError(f"{self.shown}: open: not a file path nor a database URL (docs/history.md)",
                               lasting=True)
        path = self._sqlite_path()
        if path is not None:
            self._check_file(path, create)
        with self._step("open"):
            engine = _engine(self.url)
            connection = engine.connect()
        try:
            with self._step("migrate"):
                _migrate(connection)
            with self._step(operation), connection.execution_options(hil_write=write).begin():
                yield connection
        finally:
            connection.close()
            engine.dispose()

    @contextmanager
    def _step(self, operation: str) -> Iterator[None]:
        """Any error of ``operation`` as a :class:`HistoryError`: the database, the operation, the cause."""
        try:
            yield
        except Exception as exc:  # the drivers' errors have no common base: any of them names the cause
            raise HistoryError(f"{self.shown}: {operation}: {self._cause(exc)}") from None

    def _cause(self, exc: Exception) -> str:
        """The driver's own words for ``exc`` on one line, without the statement, its parameters or a password."""
        original = getattr(exc, "orig", None)  # SQLAlchemy wraps the driver's exception
        text = _STATEMENT.sub("", str(original if original is not None else exc))
        text = " ".join(text.split()) or type(original or exc).__name__
        if isinstance(exc, ModuleNotFoundError):
            text += " (the URL's driver: for PostgreSQL, pip install 'turntable-hil[history]'; docs/history.md)"
        password = self.url.password if self.url is not None else None
        if password:
            text = text.replace(str(password), "***")
        return _PASSWORD_IN_DSN.sub(r"\1***", _PASSWORD_IN_URL.sub(r"\1***@", text))

    def _check_file(self, path: Path, create: bool) -> None:
        """Refuses a SQLite file that is not there to read, or whose directory is not there to create it in
        (a mistyped path files nowhere new); makes the default location's directory."""
        if path.exists():
            return
        if not create:
            raise HistoryError(f"{self.shown}: no trial history there (no such file; trials are filed there "
                               "as they run, or --history names another)", lasting=True)
        if path == default_location():
            path.parent.mkdir(parents=True, exist_ok=True)
        elif not path.parent.is_dir():
            raise HistoryError(f"{self.shown}: no such directory {path.parent}", lasting=True)

    def _sqlite_path(self) -> Path | None:
        url = self.url
        if url is None or url.get_backend_name() != "sqlite" or url.database in (None, "", ":memory:"):
            return None
        return Path(url.database).expanduser()


def _engine(url: URL) -> Engine:
    """An engine for ``url``: SQLite waits :data:`LOCK_TIMEOUT_S` for a lock and takes a writer's at BEGIN (so
    that a migration and a row are each one transaction, and writers queue rather than fail); PostgreSQL through
    psycopg gives up on a server that does not answer after :data:`CONNECT_TIMEOUT_S`, unless the URL says."""
    backend, driver = url.get_backend_name(), url.get_driver_name()
    if backend == "sqlite":
        engine = sa.create_engine(url, poolclass=sa.NullPool, connect_args={"timeout": LOCK_TIMEOUT_S})
        sa.event.listen(engine, "connect", _sqlite_transactions_by_hand)
        sa.event.listen(engine, "begin", _sqlite_begin)
        return engine
    timeout = {"connect_timeout": CONNECT_TIMEOUT_S} \
        if driver in ("psycopg", "psycopg2") and "connect_timeout" not in url.query else {}
    return sa.create_engine(url, poolclass=sa.NullPool, connect_args=timeout)


def _sqlite_transactions_by_hand(dbapi_connection, _record) -> None:
    dbapi_connection.isolation_level = None  # the driver's own BEGIN, deferred and never before DDL, is off


def _sqlite_begin(connection: Connection) -> None:
    write = connection.get_execution_options().get("hil_write")
    connection.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")


def _revision(connection: Connection) -> str | None:
    """The database's schema revision: Alembic's, else that of a file of versions 1-3 (its ``schema_version``
    table), else None (no schema yet)."""
    tables = sa.inspect(connection).get_table_names()
    if "alembic_version" in tables:
        return connection.execute(sa.text("SELECT version_num FROM alembic_version")).scalar()
    if "schema_version" in tables:
        version = connection.execute(sa.text("SELECT version FROM schema_version")).scalar() or 0
        if version and version not in LEGACY_REVISIONS:
            raise NewerSchema(f"schema version {version} is newer than this software knows")
        return LEGACY_REVISIONS.get(version)
    return None


def _migrate(connection: Connection) -> None:
    """Brings the database to the last revision in one transaction, under a lock that keeps other stations
    waiting (SQLite's writer lock, PostgreSQL's advisory lock); a database of a newer revision is refused."""
    current = _revision(connection)
    connection.rollback()
    if current == HEAD:
        return
    from alembic import command  # only for a database to migrate: a tenth of a second to import and read
    from alembic.config import Config
    from alembic.script import ScriptDirectory

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    script = ScriptDirectory.from_config(config)
    with connection.execution_options(hil_write=True).begin():
        if connection.dialect.name == "postgresql":
            connection.execute(sa.select(sa.func.pg_advisory_xact_lock(MIGRATION_LOCK)))
        current = _revision(connection)  # another station may have migrated it meanwhile
        if current is not None and current not in {rev.revision for rev in script.walk_revisions()}:
            raise NewerSchema(f"schema revision {current} is newer than this software's "
                              f"{script.get_current_head()}")
        config.attributes["connection"] = connection
        if current is not None and "alembic_version" not in sa.inspect(connection).get_table_names():
            command.stamp(config, current)
        command.upgrade(config, "head")
