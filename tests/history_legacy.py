"""History files as versions 1-3 of the software wrote them, by hand-written SQLite statements and a
``schema_version`` table: the migrations must bring them forward keeping every row."""

from __future__ import annotations

import sqlite3
from pathlib import Path

# the statements that took a file from version k to k + 1, as released
STEPS = (
    ("CREATE TABLE trials (id INTEGER PRIMARY KEY, kind TEXT NOT NULL, name TEXT, ended TEXT, verdict TEXT, "
     "out_dir TEXT, dut_part TEXT, dut_serial TEXT, station TEXT, operator TEXT, software_version TEXT, "
     "git_commit TEXT, config_sha256 TEXT, started_utc TEXT, ended_utc TEXT, host TEXT, figures TEXT NOT NULL)",),
    ("ALTER TABLE trials ADD COLUMN notes TEXT",
     "CREATE INDEX trials_by_unit ON trials (dut_serial, started_utc)"),
    ("ALTER TABLE trials ADD COLUMN replay_of TEXT",
     "UPDATE trials SET verdict = CASE WHEN ended LIKE 'interrupted%' THEN 'INTERRUPTED' ELSE 'ENDED EARLY' END "
     "WHERE ended <> 'completed' AND verdict IN ('PASS', 'FAIL')"),
)


def legacy_history(path: Path, version: int) -> sqlite3.Connection:
    """A history file at ``version`` (1-3) at ``path``; an open connection to add rows with (commit, close)."""
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    db.execute("INSERT INTO schema_version VALUES (?)", (version,))
    for statements in STEPS[:version]:
        for statement in statements:
            db.execute(statement)
    return db
