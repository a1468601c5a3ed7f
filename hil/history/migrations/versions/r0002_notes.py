"""Version 2: the record's notes, and the index by unit and start time.

Revision ID: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"


def upgrade() -> None:
    op.add_column("trials", sa.Column("notes", sa.Text))
    op.create_index("trials_by_unit", "trials", ["dut_serial", "started_utc"])
