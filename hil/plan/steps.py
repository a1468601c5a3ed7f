"""A plan's trial steps, each run by its own command's code: a swing step is ``hil run``, a calibrate step
``hil calibrate``, a noise step ``hil noise``, called with the arguments their command line would take (the
step's config, with its overrides and the plan's tag, written to ``OUT/configs/NN-<kind>.yaml``)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import yaml

from hil.arguments import build_parser
from hil.inputs import InputError
from hil.plan.spec import Step, merged

COMMAND_OF = {"swing": ["run"], "calibrate": ["calibrate"], "noise": ["noise"],
              "scale_factor": ["ratetest", "scale-factor"], "frequency_response": ["ratetest", "frequency-response"]}
INTERRUPTED, ENDED_EARLY = "INTERRUPTED", "ENDED EARLY"


@dataclass(frozen=True)
class StepContext:
    """What every trial step of one plan run shares: the plan's output directory, name and run, the plan
    command's arguments (speed, history, record options) and the command functions by name (:data:`hil.cli.COMMANDS`);
    ``view`` the plan's viewer (:class:`hil.viewer.plan_view.PlanView`, None: none)."""

    out: Path
    name: str
    run: str
    args: argparse.Namespace
    commands: dict[str, Callable[[argparse.Namespace], int]]
    view: object | None = None


def plan_tag(name: str, run: str, step: Step) -> str:
    """The tag a plan's trial carries in ``record.notes`` (and so in the history's ``notes``)."""
    return f"plan {name} run {run} step {step.out_name}"


def run_trial_step(step: Step, ctx: StepContext, overrides: dict) -> tuple[str, str | None, int]:
    """Run ``step`` through its command into ``OUT/NN-<kind>``, its config with ``overrides`` (the unit's state
    since its last power-on): how it ended, its verdict and its exit code."""
    config = _write_config(step, ctx, overrides)
    argv = _argv(step, config, ctx.out / step.out_name, ctx.args, "none" if ctx.view is None else "save")
    args = build_parser().parse_args(argv)
    args.func, args.started = ctx.commands[args.command], datetime.now(timezone.utc)
    if ctx.view is not None:  # a swing or calibrate step's own view in the plan's viewer, the plan's document beside
        args.plan_view = (ctx.view.grpc_url, ctx.view.text)
    try:
        code = args.func(args)
    except InputError as exc:
        print(f"hil: plan: step {step.index}: {exc}", file=sys.stderr)
        return f"refused: {exc}", ENDED_EARLY, 2
    ended, verdict = _outcome(step, ctx.out / step.out_name, code)
    return ended, verdict, code


def _write_config(step: Step, ctx: StepContext, overrides: dict) -> Path:
    """The step's config with ``overrides``, tagged with the plan's name, run and step in ``record.notes``."""
    data = merged(step.data, overrides, f"step {step.index}")
    record = dict(data.get("record") or {})
    notes = record.get("notes")
    record["notes"] = plan_tag(ctx.name, ctx.run, step) + (f"; {notes}" if notes else "")
    data["record"] = record
    path = ctx.out / "configs" / f"{step.out_name}.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _argv(step: Step, config: Path, out: Path, args: argparse.Namespace, viewer: str) -> list[str]:
    """The command line of ``step``'s own command (a swing or calibrate step's ``--viewer``: ``viewer``)."""
    command = COMMAND_OF[step.kind]
    argv = [*command, str(config), "--out", str(out), "--overwrite", "--quiet"]  # --overwrite: a re-run step
    if step.kind == "noise":
        argv += ["--duration", str(step.params["duration_s"])]
    else:
        argv += ["--speed", args.speed] + (["--viewer", viewer] if step.kind in ("swing", "calibrate") else [])
    argv += ["--no-history"] if args.no_history else ["--history", args.history] if args.history else []
    for option in ("dut", "operator", "station"):
        if getattr(args, option) is not None:
            argv += [f"--{option}", getattr(args, option)]
    return argv + (["--no-figures"] if args.no_figures else [])


def _outcome(step: Step, out: Path, code: int) -> tuple[str, str | None]:
    """How the step at ``out`` ended and its verdict, from its result.json (a noise step: noise.json; a rate
    test: scale_factor.json or frequency_response.json, judged as its exit code says)."""
    name = {"swing": "result", "calibrate": "result", "noise": "noise"}.get(step.kind, step.kind)
    result = out / f"{name}.json"
    if not result.is_file():
        return ("completed", None) if code == 0 else ("ended early: no result written", ENDED_EARLY)
    doc = json.loads(result.read_text(encoding="utf-8"))
    if step.kind == "noise":
        return ("completed", None) if code == 0 else ("ended early", ENDED_EARLY)
    ended = doc.get("ended") or "ended early"
    if ended != "completed":
        return ended, INTERRUPTED if ended.startswith("interrupted") else ENDED_EARLY
    return ended, doc["verdict"] if "verdict" in doc else {0: "PASS", 3: "FAIL"}.get(code)
