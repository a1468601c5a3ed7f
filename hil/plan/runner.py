"""``hil plan PLAN.yaml``: the plan's steps run in order into ``OUT/NN-<kind>/``, its state in ``OUT/plan.json``
after every step, ``--resume`` going on from it, ``--dry-run`` the schedule alone; on every way out the table
commanded on its own port is turned Off and the power supply brought to its ``on_exit``, both read back (each
trial turns its table Off itself too)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from drivers.scpi_supply import SupplyError
from hil.plan.power import PlanPower
from hil.plan.soak import PlanChamber
from hil.plan.spec import TRIAL_KINDS, Plan, Step, load_plan
from hil.plan.state import PlanState
from hil.plan.steps import ENDED_EARLY, INTERRUPTED, StepContext, run_trial_step
from hil.plan.table import PlanTable
from hil.trial.stop_signals import StopSignals

Commands = dict[str, Callable[[argparse.Namespace], int]]


def run_plan(args: argparse.Namespace, commands: Commands) -> int:
    """The plan ``args.plan`` run (or with ``--dry-run`` checked and its schedule printed); the exit code."""
    from emulators.process import parse_speed

    plan = load_plan(args.plan)
    speed = parse_speed(args.speed)
    power, chamber = PlanPower(plan.config, speed), PlanChamber(plan.config.environment.chamber, speed)
    power.check(plan)
    chamber.check(plan)
    if args.dry_run:
        print(schedule_text(plan, speed))
        return 0
    from hil.outputs.output_dir import claimed

    out = Path(args.out) if args.out else Path("runs") / f"plan-{plan.name}"
    with claimed(out, ()):
        state = PlanState.open(out, plan, args.resume)
        view = _view(args, out, plan)
        ctx = StepContext(out, plan.name, state.doc["run"], args, commands, view)
        devices = Devices(power, chamber, PlanTable(plan.config.turntable))
        try:
            with StopSignals() as stop, power, chamber, devices.table:  # left in reverse: the table Off first
                power.restore(plan, state)
                chamber.restore(plan, state)
                ended = _steps(plan, state, ctx, devices, stop)
            code = _close(plan, state, ended, devices, view)
        finally:
            if view is not None:
                view.close()
        if view is not None:
            from hil.trial.viewer_feed import finish_viewer

            finish_viewer(view)  # a served web viewer stays up until Ctrl-C
        return code


def _view(args: argparse.Namespace, out: Path, plan: Plan):
    """The plan's view ``--viewer`` asks for (:mod:`hil.viewer.plan_view`), or None."""
    if args.viewer == "none":
        return None
    from hil.trial.viewer_feed import started_view
    from hil.viewer.plan_view import PlanView  # rerun only when a view is asked for

    return started_view(lambda: PlanView(args.viewer, out, plan.name, args.bind), args.viewer)


def _show(view, plan: Plan, state: PlanState, step: Step | None, after: bool = False, ended: str | None = None,
          verdict: str | None = None) -> None:
    """The plan in its view (None: none) at ``step``'s start (``after``: its end; None: the plan's end), on the
    plan's scheduled time."""
    if view is None:
        return
    from hil.viewer.plan_view import plan_markdown

    done = len(plan.steps) if step is None else step.index - (0 if after else 1)
    t, left = (sum(s.duration_s for s in plan.steps[:done]), sum(s.duration_s for s in plan.steps[done:]))
    running = None if step is None or after else step.index
    view.show(t, plan_markdown(plan.name, state.doc["steps"], running, _duration(left, 1), ended, verdict), running,
              len(plan.steps))


class Devices(NamedTuple):
    """What a plan drives besides the trials: the power supply, the chamber, and the table on its way out."""

    power: PlanPower
    chamber: PlanChamber
    table: PlanTable


def _steps(plan: Plan, state: PlanState, ctx: StepContext, devices: Devices, stop: StopSignals) -> str:
    """Run the steps not done yet; how the plan ended."""
    for step in plan.steps:
        if state.done(step):
            continue
        if stop.received:
            return f"interrupted ({stop.received})"
        _progress(plan, step, devices.power.speed)
        state.start(step)
        _show(ctx.view, plan, state, step)
        ended, verdict, more = _run_step(step, ctx, devices, stop)
        state.finish(step, ended, verdict, **more)
        _show(ctx.view, plan, state, step, after=True)
        if verdict == INTERRUPTED or stop.received:
            return f"interrupted ({stop.received or 'during step ' + str(step.index)})"
        if verdict == ENDED_EARLY and step.on_failure == "stop":
            return f"ended early at step {step.index} ({step.kind}): {ended}"
    return "completed"


def _run_step(step: Step, ctx: StepContext, devices: Devices, stop: StopSignals) -> tuple[str, str | None, dict]:
    """Run one step: how it ended, its verdict and what else its entry in plan.json holds (the supply's reading
    before a trial step, a soak's end)."""
    power = devices.power
    if step.kind in TRIAL_KINDS:
        try:
            more = {"power": power.reading()} if power.supply is not None else {}
            unpowered = power.unpowered()
        except SupplyError as exc:
            return f"ended early: {exc}", ENDED_EARLY, {}
        if unpowered:
            return f"ended early: {unpowered}", ENDED_EARLY, more
        ended, verdict, _ = run_trial_step(step, ctx, {**power.overrides(), **devices.chamber.overrides()})
        return ended, verdict, more
    if step.kind == "soak":
        return devices.chamber.soak(step, stop)
    if step.kind == "wait":
        done = power.sleep(float(step.params["s"]), stop)
        return ("completed", None, {}) if done else ("interrupted", INTERRUPTED, {})
    return (*power.step(step, stop), {})


def _close(plan: Plan, state: PlanState, ended: str, devices: Devices, view) -> int:
    """The plan's end in plan.json, plan.html and junit.xml; its exit code as a trial's."""
    from hil.plan.pages import write_pages
    from hil.plan.repeatability import units_figures

    verdicts = [entry["verdict"] for entry in state.doc["steps"]]
    if ended != "completed":
        verdict = INTERRUPTED if ended.startswith("interrupted") else ENDED_EARLY
    elif ENDED_EARLY in verdicts:
        verdict = ENDED_EARLY
    else:
        verdict = "FAIL" if "FAIL" in verdicts else "PASS" if "PASS" in verdicts else None
    state.close(ended, verdict, units_figures(plan, state))
    _show(view, plan, state, None, ended=ended, verdict=verdict)
    write_pages(state)
    print(f"plan {plan.name}: {ended}, verdict {verdict or 'none judged'}; {state.out / 'plan.html'}")
    if devices.table.exit_state:
        print(f"turntable: {devices.table.exit_state}")
    if devices.power.exit_state:
        print(f"power supply: {devices.power.exit_state}")
    return {None: 0, "PASS": 0, "FAIL": 3}.get(verdict, 1)


def _progress(plan: Plan, step: Step, speed: float | None) -> None:
    """One line: the step, its index and the plan's remaining time."""
    remaining = sum(later.duration_s for later in plan.steps[step.index - 1:])
    print(f"plan {plan.name}: step {step.index}/{len(plan.steps)} {step.kind} ({step.out_name}); "
          f"{_duration(remaining, speed)} left", file=sys.stderr, flush=True)


def _duration(seconds: float, speed: float | None) -> str:
    """Trial time as a duration, and the wall time at ``speed`` where it differs."""
    text = f"{seconds / 60:.1f} min" if seconds >= 90 else f"{seconds:.0f} s"
    if speed is None:
        return f"{text} of trial time (--speed max)"
    return text if speed == 1 else f"{text} of trial time, {_duration(seconds / speed, 1)} at x{speed:g}"


def schedule_text(plan: Plan, speed: float | None) -> str:
    """The plan's schedule: every step with its duration, and the total."""
    lines = [f"plan {plan.name}: {len(plan.steps)} steps, config {plan.config_path}"]
    for step in plan.steps:
        detail = step.params if step.kind in ("power", "wait", "noise") else step.params or "the config as it is"
        where = f"  (repeat at step {step.block}, pass {step.repeat})" if step.block else ""
        cycle = f" off {step.off_s:g} s" if step.off_s is not None else ""
        lines.append(f"  {step.out_name:<14} {_duration(step.duration_s, 1):>10}  {detail}{cycle}{where}")
    lines.append(f"total {_duration(sum(step.duration_s for step in plan.steps), speed)}")
    return "\n".join(lines)
