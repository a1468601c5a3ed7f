"""The trial history (docs/history.md): every trial's record and headline figures in one database, and the
unit's run-to-run figures from it (``hil history``)."""
