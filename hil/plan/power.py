"""The plan's power supply (``environment.power``): its steps (on, off, a cycle with ``off_s``), whether the
unit is powered and drawing current before a trial step, the plan's waits, and the supply brought to its
``on_exit`` on every way out of the plan, read back. With the emulated supply, each power-on draws the unit's
new turn-on bias (``imu.errors.turn_on_bias_ug``, seeded by ``trial.seed`` and the power step's index, so that a
resumed plan draws the same), which the trial steps after it run with."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from drivers.scpi_supply import ScpiSupply, SupplyError
from hil.config import Config
from hil.inputs import InputError
from hil.plan.spec import Plan, Step
from hil.plan.steps import ENDED_EARLY, INTERRUPTED
from hil.plan.state import PlanState
from hil.trial.rig import open_supply
from hil.trial.stop_signals import StopSignals

POLL_S = 0.1  # how often a wait looks for a stop signal


class PlanPower:
    """The supply of ``config`` (none when the config has no ``environment.power``) for one plan run; waits run
    at ``speed`` (None: at once) when every device is emulated, in real time otherwise."""

    def __init__(self, config: Config, speed: float | None) -> None:
        self.config, self.speed = config, speed
        self.settings = config.environment.power
        self.emulated = config.imu.source == "emulator" and config.turntable.source == "emulator"
        self.supply: ScpiSupply | None = None
        self.server = None
        self.bias_ug: list[float] | None = None  # the emulated unit's accelerometer bias since its last power-on
        self.exit_state: str | None = None

    def check(self, plan: Plan) -> None:
        """Refuse a power step when the config names no supply."""
        if self.settings is None:
            for step in plan.steps:
                if step.kind == "power":
                    raise InputError(f"{plan.path}: step {step.index}: power: the config ({plan.config_path}) has "
                                     "no power supply (environment.power)")

    def __enter__(self) -> PlanPower:
        """Connect to the supply (start the emulated one first); one that cannot be reached is bad input."""
        if self.settings is not None:
            self.supply, self.server = open_supply(self.settings)
        return self

    def __exit__(self, *exc: object) -> None:
        """The supply's output to ``on_exit``, read back, and the connection closed."""
        if self.supply is not None:
            try:
                self.supply.output(self.settings.on_exit == "on")
                reading = self.supply.read()
                self.exit_state = (f"output {'on' if reading.output_on else 'off'} (read back), "
                                   f"{reading.voltage_v:g} V, {reading.current_a:g} A")
            except SupplyError as exc:
                self.exit_state = f"not confirmed: {exc}"
        self._close()

    def _close(self) -> None:
        if self.supply is not None:
            self.supply.close()
        if self.server is not None:
            self.server.close()
        self.supply = self.server = None

    def restore(self, plan: Plan, state: PlanState) -> None:
        """A resumed plan: the output as the last power step that ended left it (and the unit's turn-on bias)."""
        done = [step for step in plan.steps if step.kind == "power" and state.done(step)]
        if self.supply is not None and done:
            self._switch(done[-1], done[-1].params != "off")

    def unpowered(self) -> str | None:
        """Why a trial step cannot run now (the supply's output off, or the unit drawing nothing), or None."""
        if self.supply is None:
            return None
        reading = self.supply.read()
        if not reading.output_on:
            return "the unit is not powered (the power supply's output is off)"
        if reading.current_a < self.settings.min_current_a:
            return (f"the unit draws {reading.current_a:g} A after power-on (under environment.power.min_current_a "
                    f"{self.settings.min_current_a:g} A)")
        return None

    def reading(self) -> dict[str, Any] | None:
        """The supply's measured output, for the step's entry in plan.json."""
        if self.supply is None:
            return None
        reading = self.supply.read()
        return {"output_on": reading.output_on, "voltage_v": reading.voltage_v, "current_a": reading.current_a}

    def overrides(self) -> dict[str, Any]:
        """The emulated unit's errors since its last power-on, over the step's config."""
        return {} if self.bias_ug is None else {"imu": {"errors": {"accel_bias_ug": self.bias_ug}}}

    def sleep(self, seconds: float, stop: StopSignals) -> bool:
        """Wait ``seconds`` of trial time (emulated devices: at the plan's speed); False if a stop signal came."""
        wall = seconds if not self.emulated else 0.0 if self.speed is None else seconds / self.speed
        end = time.monotonic() + wall
        while not stop.received and time.monotonic() < end:
            time.sleep(min(POLL_S, max(end - time.monotonic(), 0.0)))
        return not stop.received

    def step(self, step: Step, stop: StopSignals) -> tuple[str, str | None]:
        """Run a power step: how it ended and its verdict."""
        try:
            if step.params == "cycle":
                self._switch(step, False)
                if not self.sleep(float(step.off_s), stop):
                    return "interrupted", INTERRUPTED
            self._switch(step, step.params != "off")
        except SupplyError as exc:
            return f"ended early: {exc}", ENDED_EARLY
        return "completed", None

    def _switch(self, step: Step, on: bool) -> None:
        """The output on or off (read back); a power-on of the emulated unit draws its turn-on bias."""
        self.supply.output(on)
        if on and self.settings.source == "emulator":
            from emulators.clocks import turn_on_offset_ug

            errors = self.config.imu.errors
            offset = turn_on_offset_ug(errors.turn_on_bias_ug, (self.config.trial.seed, step.index))
            self.bias_ug = (np.asarray(errors.accel_bias_ug) + offset).tolist()

