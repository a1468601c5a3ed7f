"""What every trial command shares: its config with the record options of the command line, its claimed output
directory, its viewer, and its end (outputs written, verdict shown, the trial filed in the history)."""

from __future__ import annotations

import argparse
import importlib
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path


def viewer_options(args: argparse.Namespace):
    """The live viewer the arguments ask for; a plan's step, the plan's viewer (``args.plan_view``, set by
    :func:`hil.plan.steps.run_trial_step`: its gRPC URL or None, and the plan's document)."""
    from hil.trial.viewer_feed import ViewerOptions

    connect, plan = getattr(args, "plan_view", (None, None))
    return ViewerOptions(args.viewer, args.bind, connect=connect, plan=plan)


def finish(args: argparse.Namespace, outcome, viewer=None, figures=None) -> int:
    """Write the outputs (the figures drawn by ``figures``, a :class:`~hil.outputs.figure_process.FigureProcess`,
    when given), show its judgement in the viewer, file the trial in the history, close the viewer of a completed
    trial; the exit code."""
    from hil.trial.viewer_feed import finish_viewer, show_verdict

    judged = written(args, outcome, figures)
    show_verdict(viewer, judged)
    code = outcome.exit_code(judged.verdict)
    if code == 1:
        print(f"hil: trial {outcome.ended}", file=sys.stderr)
    else:
        finish_viewer(viewer)
    return code


def written(args: argparse.Namespace, outcome, figures=None):
    """Write one trial's outputs with its record (the figures drawn by ``figures`` when given) and file it in the
    history, with its verdict, as the outcome says it is filed (:meth:`~hil.trial.outcome.TrialOutcome.filed_as`);
    its :class:`~hil.outputs.judgement.Judgement`."""
    from hil.outputs.figures import write_figures
    from hil.outputs.record import trial_record

    draw = write_figures if figures is None else figures.draw
    history = None if args.no_history or figures is None else _imported_meanwhile("hil.history.filing")
    outcome.result["record"] = trial_record(outcome.settings.record, outcome.config_text, args.started,
                                            datetime.now(timezone.utc), outcome.out)
    judged = outcome.write(figures=not args.no_figures, draw=draw)
    if not args.no_history:
        if history is not None:
            history.join()
        from hil.history.entry import outcome_row
        from hil.history.filing import file_trial

        file_trial(args.history, outcome_row(outcome.out, outcome.result, judged.verdict, *outcome.filed_as()))
    return judged


def finish_units(args: argparse.Namespace, fixture) -> int:
    """Write and file every unit's trial of a :class:`~hil.trial.units.FixtureOutcome` (:func:`written`), its
    judgement shown in its view and in the fixture's overview, then the trial's index (result.json, report.html,
    junit.xml), the overview's table of units; the units' views finished (a served web viewer then kept up until
    Ctrl-C); the exit code of the worst unit."""
    from hil.trial.viewer_feed import finish_viewer, show_verdict
    from hil.viewer.verdict import final_markdown

    verdicts = {}
    overview = fixture.overview
    for name, outcome in fixture.units.items():
        judged = written(args, outcome)
        show_verdict(fixture.viewers.get(name), judged)
        if overview is not None:
            overview.unit_verdict(name, final_markdown(judged))
        verdicts[name] = judged.verdict
        if outcome.exit_code(judged.verdict) == 1:
            print(f"hil: unit {name}: trial {outcome.ended}", file=sys.stderr)
    code = fixture.write_index()
    if overview is not None:
        overview.end(fixture.index)
    views = list(fixture.viewers.values())
    for view in views[1:]:  # connected to the first one's viewer: all sent, then disconnected from it
        view.stop()
    if views:
        finish_viewer(views[0])
    return code


def _imported_meanwhile(module: str) -> threading.Thread:
    """``module`` imported on a thread, started now: the history's SQLAlchemy (about 0.17 s) while this process
    waits for the figure process to draw."""
    thread = threading.Thread(target=importlib.import_module, args=(module,), name="import-history", daemon=True)
    thread.start()
    return thread


def record_options(args: argparse.Namespace) -> dict[str, str | None]:
    """The record's fields the command line gives (``--dut``, ``--operator``, ``--station``; None where not given)."""
    return {"dut_serial": args.dut, "operator": args.operator, "station": args.station}


def trial_config(args: argparse.Namespace, units: bool = False):
    """The trial config the arguments name, and the trial's output directory; a ``units`` config only where the
    command takes one (``units``), and then without ``--dut`` (each unit names its own), ``--operator`` and
    ``--station`` over every unit's record."""
    from hil.config import load_config
    from hil.inputs import InputError
    from hil.outputs.output_dir import output_dir

    cfg = load_config(args.config, units)
    if cfg.units and args.dut:
        raise InputError(f"--dut {args.dut}: {args.config} has several units; each names its serial in "
                         "units[i].record.dut_serial")
    record = {key: value for key, value in record_options(args).items() if value is not None}
    if record:
        units = [unit.model_copy(update={"record": unit.record.model_copy(update=record)}) for unit in cfg.units or ()]
        cfg = cfg.model_copy(update={"record": cfg.record.model_copy(update=record), "units": units or None})
    return cfg, output_dir(args.out, cfg)


@contextmanager
def claimed(args: argparse.Namespace, out: Path, *inputs: str | Path | None, noise: bool = False) -> Iterator[None]:
    """The command's output directory, claimed for the ``with`` block (:func:`hil.outputs.output_dir.claimed`;
    its ``inputs`` are never removed); a history's rows that pointed at outputs ``--overwrite`` replaced point
    nowhere."""
    from hil.history.location import forgotten, resolve
    from hil.outputs.output_dir import NOISE_OUTPUTS, TRIAL_OUTPUTS
    from hil.outputs.output_dir import claimed as claim

    given = tuple(Path(path) for path in inputs if path is not None)
    with claim(out, NOISE_OUTPUTS if noise else TRIAL_OUTPUTS, args.overwrite, given) as replaced:
        if replaced and not forgotten(resolve(args.history), str(out.resolve())):
            from hil.history.filing import forget_outputs  # SQLAlchemy: a URL, a schema to migrate, an error

            forget_outputs(args.history, out)
        yield
