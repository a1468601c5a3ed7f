"""The trial history on a real PostgreSQL server (tests/pg_server.py): trials filed with the identity key, an old
schema migrated keeping its rows, three stations filing at once, and a wrong password or an unreachable server
costing one line that never shows the password (docs/history.md, "Servers")."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext

from hil.history.spool import spool_dir
from hil.history.store import History, HistoryError
from hil.history.tables import metadata
from tests.history_legacy import STEPS
from tests.pg_server import PASSWORD, free_port, pg_history, postgres  # noqa: F401 (fixtures)
from tests.test_history import hil, short_swing

psycopg = pytest.importorskip("psycopg")  # the [history] extra


def row(dut: str, started: str, **figures) -> dict:
    return {"kind": "swing", "dut_serial": dut, "started_utc": started, "figures": figures}


def test_trials_are_filed_on_a_postgresql_server_each_with_its_own_key(pg_history):
    history = History(pg_history)
    history.append(row("A", "2026-12-01", accel_bias_ug=[1.0, 2.0, 3.0]))
    history.append(row("A", "2026-12-02"))
    assert [(t["id"], t["started_utc"], t["figures"]) for t in history.trials("A")] == [
        (1, "2026-12-01", {"accel_bias_ug": [1.0, 2.0, 3.0]}), (2, "2026-12-02", {})]
    assert history.version() == 4


@pytest.mark.parametrize("backend", ["postgresql", "sqlite"])
def test_the_migrations_build_the_schema_the_metadata_describes(backend, request, tmp_path):
    url = request.getfixturevalue("pg_history") if backend == "postgresql" else f"sqlite:///{tmp_path}/h.sqlite"
    History(url).append(row("A", "2026"))
    engine = sa.create_engine(url)
    with engine.connect() as connection:
        differences = compare_metadata(MigrationContext.configure(connection), metadata)
    engine.dispose()
    assert differences == []


def test_a_server_database_the_hand_written_schema_made_is_migrated_and_files_on_from_its_rows(postgres, pg_history):
    database = pg_history.rsplit("/", 1)[1]
    with psycopg.connect(host="127.0.0.1", port=postgres.port, user="hil", password=PASSWORD,
                         dbname=database) as connection:
        connection.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
        connection.execute("INSERT INTO schema_version VALUES (3)")
        for statement in (s for step in STEPS for s in step):
            connection.execute(statement)
        connection.execute("INSERT INTO trials (id, kind, dut_serial, started_utc, figures) "
                           "VALUES (7, 'swing', 'A', '2026', '{}')")  # filed by hand: the schema had no key
    history = History(pg_history)
    history.append(row("A", "2027"))
    assert [(t["id"], t["started_utc"]) for t in history.trials("A")] == [(7, "2026"), (8, "2027")]
    assert history.version() == 4


def test_an_error_names_the_database_and_the_operation_in_the_drivers_words_never_the_statement(pg_history):
    with pytest.raises(HistoryError) as error:
        History(pg_history).append({"kind": None, "dut_serial": "SERIAL-IN-PARAMS", "figures": {}})
    message = str(error.value)
    assert message.startswith(pg_history.replace(PASSWORD, "***") + ": file: ")
    assert 'null value in column "kind"' in message
    assert "INSERT" not in message and "SERIAL-IN-PARAMS" not in message and PASSWORD not in message


def test_three_stations_filing_at_once_give_three_runs_and_the_repeatability_of_their_result_files(
        pg_history, tmp_path):
    def trial(seed: int) -> subprocess.CompletedProcess:
        return hil("simulate", str(short_swing(tmp_path, seed)), "--dut", "X", "--out", str(tmp_path / f"run{seed}"),
                   "--no-figures", "--history", pg_history)

    with ThreadPoolExecutor(3) as pool:  # each a hil process, into a database none has migrated yet
        done = list(pool.map(trial, (1, 2, 3)))
    assert [d.returncode for d in done] == [0, 0, 0], [d.stderr for d in done]
    assert not any("warning" in d.stderr for d in done)
    shown = hil("history", "--dut", "X", "--json", "--history", pg_history)
    assert shown.returncode == 0, shown.stderr
    (unit,) = json.loads(shown.stdout)["units"]
    biases = [json.loads((tmp_path / f"run{seed}" / "result.json").read_text())["estimate"]["accel_bias_ug"]
              for seed in (1, 2, 3)]
    assert unit["runs"] == 3
    np.testing.assert_allclose(unit["accel_bias_repeatability_ug"], np.std(biases, axis=0, ddof=1), rtol=1e-12)


def _lines(done: subprocess.CompletedProcess) -> list[str]:
    return (done.stdout + done.stderr).splitlines()


def test_a_wrong_password_is_exit_2_for_hil_history_and_one_warning_for_a_trial_never_showing_it(postgres, tmp_path):
    wrong = postgres.url(password="not-the-Pw.17")
    shown = hil("history", "--history", wrong)
    assert shown.returncode == 2 and shown.stdout == ""
    (line,) = shown.stderr.splitlines()
    assert "postgresql+psycopg://hil:***@127.0.0.1" in line and ": open: " in line
    assert "password authentication failed" in line
    done = hil("simulate", str(short_swing(tmp_path, 1)), "--out", str(tmp_path / "run"), "--no-figures",
               "--history", wrong)
    assert done.returncode == 0 and (tmp_path / "run" / "result.json").exists()
    assert len([line for line in done.stderr.splitlines() if "warning" in line]) == 1
    assert not any("not-the-Pw.17" in line or PASSWORD in line for line in _lines(shown) + _lines(done))
    assert len(_spooled()) == 1
    files = [*tmp_path.rglob("*"), *_spooled()]
    assert [path for path in files if path.is_file() and b"not-the-Pw.17" in path.read_bytes()] == []


def test_a_password_the_driver_reads_from_a_pgpass_file_files_trials_under_a_url_without_it(
        postgres, pg_history, tmp_path, monkeypatch):
    pgpass = tmp_path / "pgpass"
    pgpass.write_text(f"127.0.0.1:{postgres.port}:*:hil:{PASSWORD}\n")
    pgpass.chmod(0o600)
    monkeypatch.setenv("PGPASSFILE", str(pgpass))
    history = History(pg_history.replace(f":{PASSWORD}@", "@"))
    history.append(row("P", "2026"))
    assert [t["dut_serial"] for t in history.trials()] == ["P"]


def test_a_url_whose_driver_is_not_installed_names_it_and_how_to_install_one():
    if importlib.util.find_spec("pg8000") is not None:
        pytest.skip("pg8000 is installed")
    shown = hil("history", "--history", f"postgresql+pg8000://hil:{PASSWORD}@127.0.0.1/lab")
    (line,) = shown.stderr.splitlines()
    assert shown.returncode == 2 and PASSWORD not in line
    assert ": open: No module named 'pg8000'" in line and "pip install 'turntable-hil[history]'" in line


@pytest.mark.parametrize("host", ["127.0.0.1:{port}", "no-such-host.invalid"])
def test_an_unreachable_server_is_one_line_naming_it_without_its_password(host):
    url = f"postgresql+psycopg://hil:{PASSWORD}@{host.format(port=free_port())}/lab"
    shown = hil("history", "--history", url)
    assert shown.returncode == 2
    (line,) = shown.stderr.splitlines()
    assert line.startswith(f"hil: error: {url.replace(PASSWORD, '***')}: open: ") and PASSWORD not in line


def _spooled() -> list[Path]:
    """The spool's files (under the test's own data directory, tests/conftest.py)."""
    return sorted(spool_dir().glob("*"))


def test_a_trial_the_stopped_server_missed_waits_in_the_spool_and_the_next_trial_files_it(
        postgres, pg_history, tmp_path):
    trial = subprocess.Popen([sys.executable, "-m", "hil.cli", "simulate", str(short_swing(tmp_path, 1)), "--dut", "S",
                              "--out", str(tmp_path / "run1"), "--no-figures", "--history", pg_history],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    postgres.stop()  # while the trial runs: it files at its end
    try:
        out, err = trial.communicate(timeout=300)
        assert trial.returncode == 0 and (tmp_path / "run1" / "result.json").exists()
        (warning,) = err.splitlines()
        assert "trial not filed in the history" in warning and ": open: " in warning and "kept in the spool" in warning
        (spooled,) = _spooled()
        assert PASSWORD not in spooled.read_text() and PASSWORD not in out + err
        down = hil("history", "--sync", "--history", pg_history)
        assert down.returncode == 2 and len(down.stderr.splitlines()) == 1 and PASSWORD not in down.stderr
        assert _spooled() == [spooled]  # still there, not claimed
    finally:
        postgres.start()
    second = hil("simulate", str(short_swing(tmp_path, 2)), "--dut", "S", "--out", str(tmp_path / "run2"),
                 "--no-figures", "--history", pg_history)
    assert second.returncode == 0 and "1 trial(s) from the spool filed" in second.stderr
    assert _spooled() == []
    trials = History(pg_history).trials("S")
    assert sorted(Path(t["out_dir"]).name for t in trials) == ["run1", "run2"]


def test_hil_history_sync_files_a_trial_a_wrong_password_kept_in_the_spool_once(postgres, pg_history, tmp_path):
    wrong = pg_history.replace(PASSWORD, "not-the-Pw.17")
    done = hil("simulate", str(short_swing(tmp_path, 1)), "--dut", "W", "--out", str(tmp_path / "run"),
               "--no-figures", "--history", wrong)
    assert done.returncode == 0 and len(_spooled()) == 1
    synced = hil("history", "--sync", "--dut", "W", "--json", "--history", pg_history)
    assert synced.returncode == 0 and synced.stderr.startswith("hil: 1 trial(s) from the spool filed")
    assert [t["dut_serial"] for t in json.loads(synced.stdout)["trials"]] == ["W"]
    assert _spooled() == []
    again = hil("history", "--sync", "--dut", "W", "--json", "--history", pg_history)
    assert len(json.loads(again.stdout)["trials"]) == 1 and again.stderr == ""
