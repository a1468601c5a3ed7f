"""Version 4: the schema's version is Alembic's (``alembic_version``); the ``schema_version`` table of the files
versions 1-3 wrote by hand is dropped (the history took its version from it first).

Revision ID: 0004
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"


def upgrade() -> None:
    if "schema_version" in sa.inspect(op.get_bind()).get_table_names():
        op.drop_table("schema_version")
