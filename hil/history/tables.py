"""The history's schema as SQLAlchemy Core metadata, in types every backend has: the ``trials`` table with an
identity key and its index by unit and start time. The migrations (``hil/history/migrations/``) bring a
database to it; tests/test_history_server.py checks that both describe the same schema."""

from __future__ import annotations

from sqlalchemy import Column, Identity, Index, Integer, MetaData, Table, Text

metadata = MetaData()

COLUMNS = ("kind", "name", "ended", "verdict", "out_dir", "dut_part", "dut_serial", "station", "operator", "notes",
           "software_version", "git_commit", "config_sha256", "started_utc", "ended_utc", "host", "figures",
           "replay_of")
NOT_NULL = ("kind", "figures")  # figures: a JSON object as text

trials = Table("trials", metadata,
               Column("id", Integer, Identity(), primary_key=True),
               *(Column(name, Text, nullable=name not in NOT_NULL) for name in COLUMNS))
Index("trials_by_unit", trials.c.dut_serial, trials.c.started_utc)
