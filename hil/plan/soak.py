"""A plan's soak steps (``soak: {temperature_c, stable_within_c, for_s, timeout_s}``): the chamber of
``environment.chamber`` sent to the temperature, then watched until its process value stays within
``stable_within_c`` of it for ``for_s`` (``timeout_s``: an early end); the trial steps after it run at that set
point. The emulated chamber runs for the plan in this process, on a pty, its time the plan's at ``--speed``
(``max``: as fast as it answers), read through the same controller as a real one; on every way out the
chamber goes to its ``on_exit``."""

from __future__ import annotations

import time
from typing import Any

from hil.config_environment import ChamberConfig
from hil.inputs import InputError
from hil.plan.spec import Plan, Step
from hil.plan.steps import ENDED_EARLY, INTERRUPTED
from hil.trial.stop_signals import StopSignals

POLL_S = 5.0  # trial seconds between two readings of the chamber


class PlanChamber:
    """The chamber of ``environment.chamber`` (None: none) for one plan run, at ``speed``."""

    def __init__(self, settings: ChamberConfig | None, speed: float | None) -> None:
        self.settings, self.speed = settings, speed
        self.controller = self.emulated = None
        self.set_point_c: float | None = None  # the last soak's, which the trial steps after it run at
        self.t = 0.0  # the emulated chamber's trial time

    def check(self, plan: Plan) -> None:
        """Refuse a soak step when the config names no chamber."""
        for step in plan.steps:
            if step.kind == "soak" and self.settings is None:
                raise InputError(f"{plan.path}: step {step.index}: soak: the config ({plan.config_path}) has no "
                                 "chamber (environment.chamber)")

    def __enter__(self) -> PlanChamber:
        return self

    def __exit__(self, *exc: object) -> None:
        """The chamber to its ``on_exit`` and closed."""
        from hil.trial.rig import release_chamber

        if self.controller is not None:
            release_chamber(self.controller, self.settings)
        if self.emulated is not None:
            self.emulated.close()
        self.controller = self.emulated = None

    def restore(self, plan: Plan, state) -> None:
        """A resumed plan: the set point of the last soak that completed."""
        done = [step for step in plan.steps if step.kind == "soak" and state.done(step)]
        if done:
            self.set_point_c = float(done[-1].params["temperature_c"])

    def overrides(self) -> dict[str, Any]:
        """The chamber's set point since the last soak, over a trial step's config."""
        return {} if self.set_point_c is None else {"environment": {"chamber": {"set_point_c": self.set_point_c}}}

    def soak(self, step: Step, stop: StopSignals) -> tuple[str, str | None, dict]:
        """Run a soak step: how it ended, its verdict and its figures for plan.json."""
        from drivers.watlow_f4 import ChamberError

        p = step.params
        try:
            self._open()
            self.controller.set_set_point_c(float(p["temperature_c"]))
            self.set_point_c = float(p["temperature_c"])
            waited, stable = 0.0, 0.0
            while stable < p["for_s"]:
                if waited >= p["timeout_s"]:
                    return (f"ended early: the chamber did not hold {p['temperature_c']:g} deg C within "
                            f"{p['stable_within_c']:g} for {p['for_s']:g} s in {p['timeout_s']:g} s"), ENDED_EARLY, {}
                if not self._wait(POLL_S, stop):
                    return "interrupted", INTERRUPTED, {}
                waited += POLL_S
                reading = self.controller.temperature_c()
                stable = stable + POLL_S if abs(reading - p["temperature_c"]) <= p["stable_within_c"] else 0.0
        except ChamberError as exc:
            return f"ended early: environment.chamber: {exc}", ENDED_EARLY, {}
        return "completed", None, {"soak": {"temperature_c": reading, "took_s": waited}}

    def _open(self) -> None:
        """The chamber's controller, open (the emulated chamber started first, at the last set point)."""
        from hil.trial.rig import open_plan_chamber

        if self.controller is None:
            start = self.settings.set_point_c if self.set_point_c is None else self.set_point_c
            self.controller, self.emulated = open_plan_chamber(self.settings, start)

    def _wait(self, seconds: float, stop: StopSignals) -> bool:
        """``seconds`` of trial time: the emulated chamber's moved on (paced at the plan's speed), a real one's
        waited for in real time; False if a stop signal came."""
        wall = seconds if self.emulated is None else 0.0 if self.speed is None else seconds / self.speed
        end = time.monotonic() + wall
        while not stop.received and time.monotonic() < end:
            time.sleep(min(0.1, max(end - time.monotonic(), 0.0)))
        if self.emulated is not None:
            self.t += seconds
            self.emulated.air_at(self.t)
        return not stop.received
