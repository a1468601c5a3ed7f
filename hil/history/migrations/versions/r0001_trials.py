"""Version 1: the trials table.

Revision ID: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
V1 = ("kind", "name", "ended", "verdict", "out_dir", "dut_part", "dut_serial", "station", "operator",
      "software_version", "git_commit", "config_sha256", "started_utc", "ended_utc", "host", "figures")


def upgrade() -> None:
    op.create_table("trials", sa.Column("id", sa.Integer, sa.Identity(), primary_key=True),
                    *(sa.Column(name, sa.Text, nullable=name not in ("kind", "figures")) for name in V1))
