"""The ``hil`` command line: parses the arguments and calls one runner (:mod:`hil.trial`).

Each command imports its runner when it runs, inside its ``cmd_*`` function: the parser alone starts in
about 40 ms (``hil --help``, a refused argument), where importing every runner would cost about 1.1 s before
anything is checked, and the offline commands start their child processes (the figure process, the simulation
process) before the schemas and the numerics load, so that the children's imports overlap the parent's
(docs/architecture.md, "Where each trial kind plugs in")."""

from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from pathlib import Path

DEFAULT_CONFIG = "configs/emulated_swing.yaml"
CALIBRATION_CONFIG = "configs/calibration.yaml"
EXIT_CODES = """exit codes:
  0  done (and PASS against output.limits, or no limits judged)
  1  a trial that ended early (devices lost, table not following, interlock, every sample rejected,
     bytes that decode as no frame: output.stream_timeout_s)
     or was interrupted (Ctrl-C, SIGTERM, SIGHUP): table turned off, outputs kept;
     a campaign with failed runs or ended by a signal (outputs of the runs done; --resume goes on)
  2  bad input (config, data file, port, arguments): one line on stderr naming it and the reason
  3  a trial that completed but FAILs against output.limits (see report.html, junit.xml)"""


def _config_path(text: str) -> Path:
    """:func:`hil.inputs.resolve_path`, imported when an argument is converted."""
    from hil.inputs import resolve_path

    return resolve_path(text)


def _viewer(args: argparse.Namespace):
    from hil.trial.viewer_feed import ViewerOptions

    return ViewerOptions(args.viewer, args.bind)


def _finish(args: argparse.Namespace, outcome, viewer=None, figures=None) -> int:
    """Write the outputs (the figures drawn by ``figures``, a :class:`~hil.outputs.figure_process.FigureProcess`,
    when given), file the trial in the history, close the viewer of a completed trial; the exit code."""
    from hil.outputs.figures import write_figures
    from hil.outputs.record import trial_record
    from hil.trial.viewer_feed import finish_viewer

    draw = write_figures if figures is None else figures.draw
    outcome.result["record"] = trial_record(outcome.cfg, outcome.config_text, args.started, datetime.now(timezone.utc),
                                            outcome.out)
    verdict = outcome.write(figures=not args.no_figures, draw=draw)
    if not args.no_history:
        from hil.history.entry import CALIBRATION, SWING, calibration_figures, swing_figures, trial_row
        from hil.history.filing import file_trial

        calibration = getattr(outcome, "calibration", None)  # a calibration trial's document, once fitted
        kind, figures_of = (CALIBRATION, calibration_figures(calibration or {})) if args.func is cmd_calibrate \
            else (SWING, swing_figures(outcome.result))
        file_trial(args.history, trial_row(kind, outcome.out, outcome.result, verdict, figures_of))
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


def cmd_run(args: argparse.Namespace) -> int:
    from hil.trial.live_runner import run_live

    cfg, out = _trial_config(args)
    return _finish(args, *run_live(cfg, Path(args.config), out, args.duration, args.speed, _viewer(args), args.quiet))


def cmd_calibrate(args: argparse.Namespace) -> int:
    cfg, out = _trial_config(args)
    if args.simulate:
        from hil.trial.calibration_simulation import run_calibration_simulation

        return _finish(args, *run_calibration_simulation(cfg, Path(args.config).read_text(), out, _viewer(args)))
    from hil.trial.calibration_runner import run_calibration

    return _finish(args, *run_calibration(cfg, Path(args.config), out, args.speed, _viewer(args), args.quiet))


def cmd_replay(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess  # started first: matplotlib loads while the trial runs

    with FigureProcess() as figures:
        from hil.trial.offline import run_replay

        return _finish(args, *run_replay(args.source, args.out, _viewer(args)), figures)


def cmd_simulate(args: argparse.Namespace) -> int:
    from emulators.simulation_process import SimulationProcess  # first: its child imports the emulator meanwhile
    from hil.outputs.figure_process import FigureProcess

    with SimulationProcess() as simulation, FigureProcess() as figures:
        from hil.trial.offline import run_simulation

        cfg, out = _trial_config(args)
        cfg.emulated_only(args.config, "hil simulate")
        outcome = run_simulation(cfg, Path(args.config).read_text(), out, _viewer(args), simulation)
        return _finish(args, *outcome, figures)


def cmd_estimate(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess

    with FigureProcess() as figures:
        from hil.trial.offline import run_csv

        cfg, out = _trial_config(args)
        return _finish(args, run_csv(cfg, Path(args.config).read_text(), args.data, out), None, figures)


def cmd_noise(args: argparse.Namespace) -> int:
    from hil.outputs.noise import noise_summary
    from hil.outputs.record import noise_record
    from hil.trial.noise_acquisition import AcquisitionFailed
    from hil.trial.noise_runner import run_noise

    out = Path(args.out) if args.out else Path("runs") / f"noise-{Path(args.source).stem}"
    given = {"dut_serial": args.dut, "operator": args.operator, "station": args.station}
    try:
        doc = run_noise(args.source, out, args.config, figure=not args.no_figures, export=args.export,
                        rerun=args.rerun, taus=args.taus, duration=args.duration, quiet=args.quiet,
                        record=lambda cfg: noise_record(given, args.source, cfg, args.started,
                                                        datetime.now(timezone.utc)))
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

    return show_history(args.history, args.dut, args.since, args.json, Path(args.out) if args.out else None)


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


def cmd_emulate(args: argparse.Namespace) -> int:
    from emulators.command import emulate
    from hil.config import load_config
    from hil.inputs import InputError

    try:
        return emulate(load_config(args.config), args)
    except OSError as exc:  # e.g. a --link-dir that cannot be written
        raise InputError(str(exc)) from None


def _config_argument(p: argparse.ArgumentParser, default: str = DEFAULT_CONFIG) -> None:
    p.add_argument("config", nargs="?", type=_config_path, default=default,
                   help=f"trial YAML, a path or a shipped config's name (default {default})")


def _live_options(p: argparse.ArgumentParser) -> None:
    from emulators.command import speed_option

    p.add_argument("--speed", default="1", type=speed_option,
                   help="emulated trials: X times real time, or 'max' (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def _trial_options(p: argparse.ArgumentParser, out_default: str = "output.dir or runs/NAME-TIME",
                   viewer_default: str | None = None) -> None:
    from hil.viewer.modes import VIEWER_MODES, default_viewer_mode

    p.add_argument("--out", help=f"output directory (default: {out_default})")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    default = viewer_default or default_viewer_mode()
    p.add_argument("--viewer", choices=VIEWER_MODES, default=default,
                   help=f"Rerun viewer: native window, web viewer, .rrd file only, or nothing (default {default})")
    p.add_argument("--bind", default="127.0.0.1", help="address the web viewer listens on (default 127.0.0.1)")


def _record_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dut", help="the unit's serial number (record.dut_serial)")
    p.add_argument("--operator", help="who runs the trial (record.operator)")
    p.add_argument("--station", help="the test station (record.station)")


def _history_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--history", metavar="URL", help="the trial history: a SQLite file or a SQLAlchemy URL "
                   "(default $HIL_HISTORY, else history.sqlite under the user's data directory; docs/history.md)")
    p.add_argument("--no-history", action="store_true", help="do not file the trial in the history")


class _Parser(argparse.ArgumentParser):
    """An argument parser whose refusal is one line on stderr naming the argument and the reason, exit 2."""

    def error(self, message: str):
        self.exit(2, f"hil: error: {message} ({self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from emulators.command import add_options as add_emulate_options  # argparse only: no emulator loaded
    from emulators.command import positive

    parser = _Parser(prog="hil", description="Turntable IMU trials: emulate, acquire, estimate.",
                                     epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a trial: devices (or their emulators) -> recorder, estimator, viewer")
    _config_argument(p)
    _trial_options(p)
    _record_options(p)
    _history_options(p)
    p.add_argument("--duration", type=positive, help="seconds (default: trial.duration_s)")
    _live_options(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("calibrate", help="multi-position calibration: the harness turns the table through the "
                                         "schedule; OUT/calibration.json")
    _config_argument(p, CALIBRATION_CONFIG)
    _trial_options(p)
    _record_options(p)
    _history_options(p)
    _live_options(p)
    p.add_argument("--simulate", action="store_true",
                   help="the emulated table and IMU in this process, as fast as the CPU allows (no ports, no "
                        "recording; --speed does not apply)")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("replay", help="re-run the processing on a recording; same results as the live run")
    p.add_argument("source", help="a run directory (its recording.mcap) or a recording file")
    _trial_options(p, out_default="RUN_DIR/replay")
    _history_options(p)
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("simulate", help="emulator straight into the estimator, as fast as possible")
    _config_argument(p)
    _trial_options(p, viewer_default="none")
    _record_options(p)
    _history_options(p)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("estimate", help="the estimator on a CSV of increments exported from other software")
    p.add_argument("data", help="CSV: t_s, dtheta_[xyz]_rad, dv_[xyz]_mps[, outer_deg, middle_deg, inner_deg]")
    p.add_argument("--config", required=True, type=_config_path, help="trial YAML (trial and site are enough)")
    p.add_argument("--out", help="output directory (default: output.dir or runs/NAME-TIME)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    _record_options(p)
    _history_options(p)
    p.set_defaults(func=cmd_estimate)

    p = sub.add_parser("noise", help="Allan deviation and IEEE noise terms of a config (its devices read, or "
                                     "simulated), run or CSV")
    p.add_argument("source", help="a trial config (devices on ports: a static record acquired into OUT/acquisition; "
                                  "emulated: simulated), a run directory or recording, or a CSV of increments")
    p.add_argument("--duration", type=positive, help="seconds to acquire from devices, or to simulate (default: "
                                                   "trial.duration_s)")
    p.add_argument("--quiet", action="store_true", help="no progress line while acquiring")
    p.add_argument("--out", help="output directory (default: runs/noise-NAME)")
    p.add_argument("--config", type=_config_path, help="for a CSV of a moving trial: its site and table")
    p.add_argument("--export", type=Path, help="also write the increments analysed as a CSV here")
    p.add_argument("--no-figures", action="store_true", help="skip allan.png")
    p.add_argument("--rerun", action="store_true", help="also write the Allan deviation curves as OUT/noise.rrd")
    p.add_argument("--taus", default="octave", help="tau grid of the deviation: octave (default), decade (1, 2, 5 x "
                                                    "10^k s), all (every multiple of the period: n^2/2 operations), "
                                                    "or taus in s such as 1,10,100,3600")
    _record_options(p)
    _history_options(p)
    p.set_defaults(func=cmd_noise)

    p = sub.add_parser("history", help="a unit's trials from the trial history: bias repeatability, drift, "
                                       "calibration and noise terms over time")
    p.add_argument("--dut", help="the unit's serial number (record.dut_serial); default every unit")
    p.add_argument("--since", help="only trials started on or after this date (ISO 8601, UTC)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON (docs/contracts.md)")
    p.add_argument("--out", help="write history.html with the plots into this directory")
    p.add_argument("--history", metavar="URL", help="the history database (default $HIL_HISTORY, else the "
                   "user's data directory)")
    p.set_defaults(func=cmd_history)

    p = sub.add_parser("campaign", help="Monte Carlo: every sweep point x N seeds of simulated trials on dask.distributed; "
                                        "OUT/runs.parquet, summary.json, campaign.html (exit 1: some runs failed)")
    p.add_argument("spec", help="campaign YAML: {base: CONFIG, runs: N, seed: S, kind: swing|noise|calibration, "
                                   "sweep: {dotted.key: [values]}}")
    p.add_argument("--scheduler", metavar="ADDR", help="an existing cluster's scheduler, tcp://host:8786 (default: a LocalCluster on "
                                       "127.0.0.1)")
    p.add_argument("--workers", type=int, metavar="N", help="LocalCluster: worker processes (default: one a core); --scheduler: "
                                               "wait for this many")
    p.add_argument("--out", help="output directory (default: runs/campaign-SPEC)")
    p.add_argument("--resume", action="store_true", help="go on with OUT/runs.parquet: skip the runs done there")
    p.set_defaults(func=cmd_campaign)

    p = sub.add_parser("worker", help="dask workers for an existing cluster, with the campaign's worker settings "
                                      "(profiler off, no malloc trim, one thread each); runs until a signal")
    p.add_argument("scheduler", help="the cluster's scheduler, tcp://host:8786")
    p.add_argument("--nworkers", type=int, default=1, metavar="N", help="worker processes (default 1)")
    p.add_argument("--host", help="the address the workers listen on (default: dask's choice)")
    p.set_defaults(func=cmd_worker)

    p = sub.add_parser("emulate", help="start the emulated devices on pseudo-terminals and print their ports; "
                                       "their statistics on stderr at the end and on a signal")
    _config_argument(p)
    add_emulate_options(p)
    p.set_defaults(func=cmd_emulate)

    p = sub.add_parser("report", help="rebuild a trial's report.html and junit.xml from its outputs (exit as its "
                                      "verdict), or a noise characterisation's report.html")
    p.add_argument("dir", help="a trial's output directory (result.json, series.csv, config.yaml) or hil noise's "
                               "(noise.json)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("decode", help="decode a raw capture to CSV; counters (auto: and the protocol) as JSON on the "
                                      "last line")
    p.add_argument("protocol", help="a protocol's name (kvh1750, xsens-mtdata2, stim300, tts1, can-dbc, or an "
                                    "installed plug-in's), or auto (named from a byte dump's first 64 kB; not for CAN "
                                    "logs)")
    p.add_argument("file", help="a raw byte dump, or a python-can .blf/.asc log for can-dbc")
    p.add_argument("--out", help="CSV to write (default: stdout is not used; counters only)")
    p.add_argument("--dbc", help="DBC file for can-dbc")
    p.add_argument("--rate", type=positive, default=200.0, help="the device's output rate, Hz (default 200; a STIM300 "
                                                            "needs its sample rate)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="one of the device's output settings, as imu.options takes it (repeatable)")
    p.set_defaults(func=cmd_decode)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.started = datetime.now(timezone.utc)
    from hil.inputs import InputError  # no schema yet: a command that starts a child does so first

    try:
        return args.func(args)
    except InputError as exc:
        print(f"hil: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hil: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
