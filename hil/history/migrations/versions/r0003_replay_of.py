"""Version 3: a replay names the run directory of the trial it re-processed (``replay_of``); a trial that did
not complete is never PASS or FAIL (rows filed before that rule are brought to it).

Revision ID: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"


def upgrade() -> None:
    op.add_column("trials", sa.Column("replay_of", sa.Text))
    op.execute("UPDATE trials SET verdict = CASE WHEN ended LIKE 'interrupted%' THEN 'INTERRUPTED' "
               "ELSE 'ENDED EARLY' END WHERE ended <> 'completed' AND verdict IN ('PASS', 'FAIL')")
