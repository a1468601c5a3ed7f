"""A PostgreSQL server of its own for the test session, in a temporary directory (initdb + pg_ctl, on 127.0.0.1
at a free port, password authentication), run as the unprivileged ``postgres`` user when the tests run as root;
the tests that need it skip when PostgreSQL's binaries are not installed (.ci/run installs them)."""

from __future__ import annotations

import glob
import itertools
import os
import shutil
import socket
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest

USER, PASSWORD = "hil", "s3cret-Pw.42"
_DATABASES = itertools.count()


def _binaries() -> Path | None:
    """The directory of initdb and pg_ctl: on the PATH, else Debian's /usr/lib/postgresql/N/bin."""
    found = shutil.which("initdb")
    if found:
        return Path(os.path.realpath(found)).parent
    debian = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    return Path(debian[-1]).parent if debian else None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class PostgresServer:
    """A running server: ``url(database)`` names a database on it, ``stop`` and ``start`` it."""

    bin: Path
    data: Path
    port: int

    def _run(self, *args: str) -> None:
        as_user = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
        subprocess.run([*as_user, str(self.bin / args[0]), *args[1:]], check=True, capture_output=True, timeout=60)

    def start(self) -> None:
        options = (f"-p {self.port} -c listen_addresses=127.0.0.1 -k {self.data.parent} -c fsync=off "
                   "-c synchronous_commit=off -c full_page_writes=off -c shared_buffers=16MB -c max_connections=30")
        self._run("pg_ctl", "-D", str(self.data), "-l", str(self.data.parent / "log"), "-w", "-o", options, "start")

    def stop(self) -> None:
        self._run("pg_ctl", "-D", str(self.data), "-w", "-m", "fast", "stop")

    def url(self, database: str = "postgres", password: str = PASSWORD) -> str:
        return f"postgresql+psycopg://{USER}:{password}@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """The URL of a new, empty database on the server."""
        import psycopg

        name = f"h{next(_DATABASES)}"
        with psycopg.connect(host="127.0.0.1", port=self.port, user=USER, password=PASSWORD, dbname="postgres",
                             autocommit=True) as connection:
            connection.execute(f"CREATE DATABASE {name}")
        return self.url(name)


@pytest.fixture(scope="session")
def postgres():
    """The session's PostgreSQL server (skips without PostgreSQL's binaries or psycopg)."""
    pytest.importorskip("psycopg")
    binaries = _binaries()
    if binaries is None:
        pytest.skip("PostgreSQL is not installed (initdb)")
    top = Path(tempfile.mkdtemp(prefix="hil-postgres-"))
    os.chmod(top, 0o755)
    password_file = top / "password"
    password_file.write_text(PASSWORD + "\n")
    if os.geteuid() == 0:
        shutil.chown(top, "postgres")
        shutil.chown(password_file, "postgres")
    server = PostgresServer(binaries, top / "data", free_port())
    server._run("initdb", "-D", str(server.data), "-U", USER, "--auth=scram-sha-256", f"--pwfile={password_file}",
                "--no-sync")
    server.start()
    try:
        yield server
    finally:
        server.stop()
        shutil.rmtree(top, ignore_errors=True)


@pytest.fixture
def pg_history(postgres) -> str:
    """The URL (with its password) of a new database on the session's server."""
    return postgres.new_database()
