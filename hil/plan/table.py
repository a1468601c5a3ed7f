"""The plan's turntable: on every way out of a plan whose config commands the table on its own port (a lab's
table, or ``hil emulate``'s), every axis Off, read back, after the steps and before the supply and the chamber
go to their ``on_exit``. An emulated trial's table (``command_port: emulator``) lives and ends with its trial."""

from __future__ import annotations

from hil.config import TurntableConfig


class PlanTable:
    """The ``turntable`` block's table (none without a command port of its own), sent Off when the plan ends."""

    def __init__(self, table: TurntableConfig) -> None:
        port = table.command_port
        self.table = table
        self.url = port if port and port != "emulator" else None
        self.exit_state: str | None = None

    def __enter__(self) -> PlanTable:
        return self

    def __exit__(self, *exc: object) -> None:
        """Every axis Off and the modes read back; what the table said in :attr:`exit_state`."""
        from hil.trial.rig import table_off

        if self.url is not None:
            self.exit_state = table_off(self.url, self.table)
