"""Alembic's environment: the migrations run on the connection the history opened (``connection`` in the
config's attributes), inside its transaction (hil/history/store.py)."""

from alembic import context

from hil.history.tables import metadata

context.configure(connection=context.config.attributes["connection"], target_metadata=metadata)
with context.begin_transaction():
    context.run_migrations()
