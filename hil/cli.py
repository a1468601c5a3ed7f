"""The ``hil`` command line: the arguments parsed (:mod:`hil.arguments`), it calls one runner (:mod:`hil.trial`).

Each command imports its runner when it runs, inside its ``cmd_*`` function: the parser alone starts in
about 40 ms (``hil --help``, a refused argument), where importing every runner would cost about 1.1 s before
anything is checked, and the offline commands start their child processes (the figure process, the simulation
process) before the schemas and the numerics load, so that the children's imports overlap the parent's
(docs/architecture.md, "Where each trial kind plugs in")."""

from __future__ import annotations

import signal
import sys

from hil import interrupted_at_start

if __name__ == "__main__":  # python -m hil.cli (the console script's start is hil's, in hil/__init__.py)
    signal.signal(signal.SIGINT, interrupted_at_start)

import argparse  # noqa: E402 (after the handler: a Ctrl-C during these imports is one line too)
import json  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from pathlib import Path  # noqa: E402

from hil.arguments import build_parser  # noqa: E402

def _viewer(args: argparse.Namespace):
    from hil.trial.viewer_feed import ViewerOptions

    return ViewerOptions(args.viewer, args.bind)


def _finish(args: argparse.Namespace, outcome, viewer=None, figures=None) -> int:
    """Write the outputs (the figures drawn by ``figures``, a :class:`~hil.outputs.figure_process.FigureProcess`,
    when given), show its verdict in the viewer, file the trial in the history, close the viewer of a completed
    trial; the exit code."""
    from hil.outputs.figures import write_figures
    from hil.outputs.record import trial_record
    from hil.trial.viewer_feed import finish_viewer, show_verdict

    draw = write_figures if figures is None else figures.draw
    outcome.result["record"] = trial_record(outcome.cfg, outcome.config_text, args.started, datetime.now(timezone.utc),
                                            outcome.out)
    verdict = outcome.write(figures=not args.no_figures, draw=draw)
    show_verdict(viewer, outcome.result, outcome.cfg.limits)
    if not args.no_history:
        from hil.history.entry import CALIBRATION, SWING, calibration_figures, swing_figures, trial_row
        from hil.history.filing import file_trial

        calibration = getattr(outcome, "calibration", None)  # a calibration trial's document, once fitted
        kind, figures_of = (CALIBRATION, calibration_figures(calibration or {})) if args.func is cmd_calibrate \
            else (SWING, swing_figures(outcome.result))
        file_trial(args.history, trial_row(kind, outcome.out, outcome.result, verdict, figures_of,
                                           getattr(outcome, "replay_of", None)))  # a replay's trial
    code = outcome.exit_code(verdict)
    if code == 1:
        print(f"hil: trial {outcome.ended}", file=sys.stderr)
    else:
        finish_viewer(viewer)
    return code


def _trial_config(args: argparse.Namespace):
    """The trial config the arguments name, and the trial's output directory."""
    from hil.config import load_config
    from hil.trial.outcome import output_dir

    cfg = load_config(args.config)
    given = {"dut_serial": args.dut, "operator": args.operator, "station": args.station}  # _record_options
    record = {key: value for key, value in given.items() if value is not None}
    if record:
        cfg = cfg.model_copy(update={"record": cfg.record.model_copy(update=record)})
    return cfg, output_dir(args.out, cfg)


@contextmanager
def _claimed(args: argparse.Namespace, out: Path, *inputs: str | Path | None, noise: bool = False) -> Iterator[None]:
    """The command's output directory, claimed for the ``with`` block (:func:`hil.outputs.output_dir.claimed`;
    its ``inputs`` are never removed); a history's rows that pointed at outputs ``--overwrite`` replaced point
    nowhere."""
    from hil.outputs.output_dir import NOISE_OUTPUTS, TRIAL_OUTPUTS, claimed

    given = tuple(Path(path) for path in inputs if path is not None)
    with claimed(out, NOISE_OUTPUTS if noise else TRIAL_OUTPUTS, args.overwrite, given) as replaced:
        if replaced:
            from hil.history.filing import forget_outputs

            forget_outputs(args.history, out)
        yield


def cmd_run(args: argparse.Namespace) -> int:
    from hil.trial.live_runner import run_live

    cfg, out = _trial_config(args)
    with _claimed(args, out, args.config):
        return _finish(args, *run_live(cfg, Path(args.config), out, args.duration, args.speed, _viewer(args),
                                       args.quiet))


def cmd_calibrate(args: argparse.Namespace) -> int:
    cfg, out = _trial_config(args)
    with _claimed(args, out, args.config):
        if args.simulate:
            from hil.trial.calibration_simulation import run_calibration_simulation

            return _finish(args, *run_calibration_simulation(cfg, Path(args.config).read_text(), out, _viewer(args)))
        from hil.trial.calibration_runner import run_calibration

        return _finish(args, *run_calibration(cfg, Path(args.config), out, args.speed, _viewer(args), args.quiet))


def cmd_ratetest(args: argparse.Namespace) -> int:
    from hil.ratetest_command import ratetest_command

    return ratetest_command(args)


def cmd_replay(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess  # started first: matplotlib loads while the trial runs

    with FigureProcess() as figures:
        from hil.inputs import InputError
        from hil.recording.replay import recording_path
        from hil.trial.offline import run_replay

        recorded = recording_path(args.source).parent
        out = Path(args.out) if args.out else recorded / "replay"
        if out.resolve() == recorded.resolve():
            raise InputError(f"--out {out}: the recording's own directory; a replay writes beside it (default "
                             f"{recorded / 'replay'})")
        with _claimed(args, out):
            return _finish(args, *run_replay(args.source, out, _viewer(args)), figures)


def cmd_simulate(args: argparse.Namespace) -> int:
    from emulators.simulation_process import SimulationProcess  # first: its child imports the emulator meanwhile
    from hil.outputs.figure_process import FigureProcess

    with SimulationProcess() as simulation, FigureProcess() as figures:
        from hil.trial.offline import run_simulation

        cfg, out = _trial_config(args)
        cfg.emulated_only(args.config, "hil simulate")
        with _claimed(args, out, args.config):
            outcome = run_simulation(cfg, Path(args.config).read_text(), out, _viewer(args), simulation)
            return _finish(args, *outcome, figures)


def cmd_estimate(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess

    with FigureProcess() as figures:
        from hil.trial.offline import run_csv

        cfg, out = _trial_config(args)
        with _claimed(args, out, args.config, args.data):
            return _finish(args, run_csv(cfg, Path(args.config).read_text(), args.data, out), None, figures)


def cmd_noise(args: argparse.Namespace) -> int:
    out = Path(args.out) if args.out else Path("runs") / f"noise-{Path(args.source).stem}"
    with _claimed(args, out, args.source, args.config, noise=True):
        return _noise(args, out)


def _noise(args: argparse.Namespace, out: Path) -> int:
    """``hil noise`` into its claimed directory ``out``."""
    from hil.outputs.noise import noise_summary
    from hil.outputs.record import noise_record
    from hil.trial.noise_acquisition import AcquisitionFailed
    from hil.trial.noise_runner import run_noise

    given = {"dut_serial": args.dut, "operator": args.operator, "station": args.station}
    try:
        doc = run_noise(args.source, out, args.config, figure=not args.no_figures, export=args.export,
                        rerun=args.rerun, taus=args.taus, duration=args.duration, quiet=args.quiet,
                        record=lambda cfg: noise_record(given, args.source, cfg, args.started,
                                                        datetime.now(timezone.utc)), detrend=args.detrend)
    except AcquisitionFailed as exc:
        print(f"hil: noise: {exc}", file=sys.stderr)
        return exc.exit_code
    print(noise_summary(doc, out))
    if not args.no_history:
        from hil.history.entry import NOISE, noise_figures, trial_row
        from hil.history.filing import file_trial

        result = {"trial": doc["trial"], "ended": "completed", "record": doc["record"]}
        file_trial(args.history, trial_row(NOISE, out, result, None, noise_figures(doc)))
    return 0


def cmd_history(args: argparse.Namespace) -> int:
    from hil.history.show import show_history

    return show_history(args.history, args.dut, args.since, args.json, Path(args.out) if args.out else None,
                        args.sync)


def cmd_campaign(args: argparse.Namespace) -> int:
    from hil.campaign.runner import run_campaign

    out = Path(args.out) if args.out else Path("runs") / f"campaign-{Path(args.spec).stem}"
    return run_campaign(args.spec, out, args.scheduler, args.workers, args.resume)


def cmd_worker(args: argparse.Namespace) -> int:
    from hil.campaign.workers import run_workers

    return run_workers(args.scheduler, args.nworkers, args.host)


def cmd_report(args: argparse.Namespace) -> int:
    from hil.outputs.result import verdict_exit_code
    from hil.outputs.trial_report import rebuild_report

    path, verdict = rebuild_report(Path(args.dir))
    print(path)
    return verdict_exit_code(verdict)


def cmd_decode(args: argparse.Namespace) -> int:
    from drivers.capture import decode_capture, detect_capture

    import yaml

    from hil.inputs import InputError

    options = {}
    for item in args.option:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError(f"--option {item}: expected KEY=VALUE")
        options[key] = yaml.safe_load(value)
    auto = args.protocol == "auto"
    protocol = detect_capture(args.file) if auto else args.protocol
    counters = decode_capture(protocol, args.file, out_csv=args.out, dbc=args.dbc, rate_hz=args.rate, **options)
    print(json.dumps({"protocol": protocol, **counters} if auto else counters))
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    from hil.plan.runner import run_plan

    return run_plan(args, COMMANDS)


def cmd_emulate(args: argparse.Namespace) -> int:
    from emulators.command import emulate
    from hil.config import load_config
    from hil.inputs import InputError

    try:
        return emulate(load_config(args.config), args)
    except OSError as exc:  # e.g. a --link-dir that cannot be written
        raise InputError(str(exc)) from None


# the function of each command, by the name the parser gives it
COMMANDS = {"run": cmd_run, "calibrate": cmd_calibrate, "ratetest": cmd_ratetest, "replay": cmd_replay,
            "simulate": cmd_simulate, "estimate": cmd_estimate, "noise": cmd_noise, "history": cmd_history,
            "campaign": cmd_campaign, "worker": cmd_worker, "report": cmd_report, "decode": cmd_decode,
            "emulate": cmd_emulate, "plan": cmd_plan}


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (default: the command line's) names; its exit code. Ctrl-C at any moment but a
    trial's (which ends the trial as interrupted, :mod:`hil.trial.stop_signals`), from the parsing of the
    arguments on, is one line and exit 130."""
    try:
        if signal.getsignal(signal.SIGINT) is interrupted_at_start:
            signal.signal(signal.SIGINT, signal.default_int_handler)  # caught below from here on
        return _command(argv)
    except BaseException as exc:
        if not _interrupted(exc):
            raise
        print("hil: interrupted", file=sys.stderr)
        return 130


def _interrupted(exc: BaseException | None) -> bool:
    """Whether ``exc`` is a Ctrl-C's KeyboardInterrupt or was raised by one (Python wraps one raised in a class
    body's ``__set_name__`` into a RuntimeError, for instance)."""
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def _command(argv: list[str] | None) -> int:
    """The arguments parsed and their command run; bad input is one line and exit 2."""
    args = build_parser().parse_args(argv)
    args.func, args.started = COMMANDS[args.command], datetime.now(timezone.utc)
    from hil.inputs import InputError  # no schema yet: a command that starts a child does so first

    try:
        return args.func(args)
    except InputError as exc:
        print(f"hil: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
