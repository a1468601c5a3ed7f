"""The history's schema migrations as Alembic revisions (``versions/``), one a schema version; opening a
database runs those it lacks (hil/history/store.py)."""
