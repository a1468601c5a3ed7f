"""The ``hil`` command line: run, replay, simulate, estimate, emulate, decode, report."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

DEFAULT_CONFIG = "configs/emulated_swing.yaml"
EXIT_CODES = """exit codes:
  0  done (and PASS against output.limits, or no limits judged)
  1  a trial that ended early (devices lost, table not following, interlock, every sample rejected)
     or was interrupted (Ctrl-C, SIGTERM, SIGHUP): table turned off, outputs kept
  2  bad input (config, data file, port, arguments): one line on stderr naming it and the reason
  3  a trial that completed but FAILs against output.limits (see report.html, junit.xml)"""


class UsageError(ValueError):
    """A command that cannot be carried out as asked."""


def _config_path(text: str) -> Path:
    """:func:`hil.config.resolve_path`, imported when an argument is converted: ``--help`` needs no pydantic."""
    from hil.config import resolve_path

    return resolve_path(text)


def _out_dir(args: argparse.Namespace, name: str, configured: str | None) -> Path:
    if args.out:
        return Path(args.out)
    return Path(configured) if configured else Path("runs") / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}"


def _finish(args: argparse.Namespace, cfg, out: Path, result: dict, snapshots: list, config_text: str,
            ended: str) -> str:
    """Write result.json (with how the trial ``ended``), series.csv, config.yaml, the figures, report.html
    and junit.xml, and print the summary; returns the overall outcome against ``output.limits``."""
    from hil.report import measurements, overall, write_report
    from hil.results import summary_text, write_outputs

    result = {"trial": result["trial"], "ended": ended, **{k: v for k, v in result.items() if k != "trial"}}
    write_outputs(out, result, snapshots, figures=cfg.output.figures and not args.no_figures, config_text=config_text)
    write_report(out, cfg.output.limits)
    outcome = overall(measurements(result, cfg.output.limits))
    print(summary_text(result, out))
    print(f"  report: {outcome} against output.limits ({out / 'report.html'})")
    return outcome


def _exit_code(ended: str, outcome: str) -> int:
    """DESIGN.md's exit codes: 1 a trial that ended early or was interrupted, 3 one that FAILs its limits."""
    from hil.report import FAIL
    from hil.results import COMPLETED

    if ended != COMPLETED:
        print(f"hil: trial {ended}", file=sys.stderr)
        return 1
    return 3 if outcome == FAIL else 0


def _viewer(args: argparse.Namespace, cfg, out: Path, blocking: bool):
    """The Rerun viewer ``--viewer`` asks for (None for ``none``)."""
    if args.viewer == "none":
        return None
    import numpy as np

    from hil.frames import TableGeometry
    from hil.units import UG
    from hil.viz import TrialViewer

    truth = np.array(cfg.imu.errors.accel_bias_ug) * UG if cfg.imu.source == "emulator" else None
    try:
        viewer = TrialViewer(args.viewer, out, geometry=TableGeometry.from_config(cfg.turntable), truth_bias=truth,
                             bind=args.bind, recording_name=cfg.trial.name, blocking=blocking)
    except Exception as exc:  # noqa: BLE001 - whatever the viewer's process or port did, say it in one line
        raise UsageError(f"--viewer {args.viewer}: the viewer did not start: {exc}") from None
    if viewer.url:
        print(f"web viewer: {viewer.url}", file=sys.stderr)
    return viewer


def _close_viewer(viewer) -> None:
    """Finish the .rrd; a served web viewer stays up until Ctrl-C."""
    if viewer is None:
        return
    viewer.close()
    if viewer.mode == "serve":
        print(f"viewer serving at {viewer.url}; Ctrl-C to stop", file=sys.stderr)
        try:
            while viewer.viewer_process is not None and viewer.viewer_process.poll() is None:
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass
        viewer.stop()


def cmd_run(args: argparse.Namespace) -> int:
    """``hil run``: exit 0 done, 1 ended early or interrupted (outputs kept), 2 bad input, 3 FAILs its limits."""
    from hil.config import load_config
    from hil.results import COMPLETED
    from hil.stop_signals import StopSignals

    config_path = Path(args.config)
    cfg = load_config(config_path)
    speed = _speed(args.speed)
    emulated = {cfg.imu.source, cfg.turntable.source} == {"emulator"}
    if not emulated and "emulator" in {cfg.imu.source, cfg.turntable.source}:
        raise UsageError("imu.source and turntable.source: emulate both devices or neither")
    duration = args.duration if args.duration is not None else cfg.trial.duration_s
    if emulated and duration is None:
        raise UsageError("an emulated trial needs trial.duration_s or --duration")
    if emulated and cfg.imu.protocol == "can-dbc" and cfg.imu.can is not None and cfg.imu.can.interface == "virtual":
        raise UsageError("imu.can.interface: 'virtual' reaches only its own process, and the emulated devices run "
                         "in theirs; use udp_multicast (the default without an imu.can block)")
    out = _out_dir(args, cfg.trial.name, cfg.output.dir)
    out.mkdir(parents=True, exist_ok=True)
    config_text = config_path.read_text()
    with StopSignals() as signals:
        trial, ended = _acquire(args, cfg, config_path, config_text, out, duration, speed if emulated else 1.0,
                                lambda: signals.received)
        processor = trial.processor
        snapshots = processor.estimator.snapshots if processor.estimator is not None else []
        outcome = _finish(args, cfg, out, processor.result(), snapshots, config_text, ended)
    if ended == COMPLETED:
        _close_viewer(trial.viewer)
    return _exit_code(ended, outcome)


def _acquire(args: argparse.Namespace, cfg, config_path: Path, config_text: str, out: Path, duration: float | None,
             time_scale: float | None, stop_requested):
    """The live part of ``hil run``: emulator (if emulated), viewer, table control and the trial; the table
    is sent Off, the viewer closed and the emulator reaped on every way out. Returns the finished trial and
    how it ended."""
    from drivers.table_client import InterlockError, LimitError, TableError
    from emulators.process import EmulatorError, spawn_emulator, stop_emulator
    from hil.live import LiveTrial
    from hil.progress import ConsoleProgress
    from hil.table_control import MotionCheck, TableControl

    emulated = {cfg.imu.source, cfg.turntable.source} == {"emulator"}
    emulator, ports, control, viewer = None, None, None, None
    try:
        if emulated:
            try:
                emulator, ports = spawn_emulator(config_path, out / "ports.json", args.speed, duration,
                                                 stats_file=out / "emulator.json", log_file=out / "emulator.log",
                                                 hold=True)
            except EmulatorError as exc:
                raise UsageError(f"{config_path}: {exc}") from None
        viewer = _viewer(args, cfg, out, blocking=False)
        command_url = _command_url(cfg, ports)
        with ConsoleProgress(duration, quiet=args.quiet) as progress:
            check = None
            if command_url is not None:
                control = TableControl(command_url, cfg.turntable)
                control.open()
                control.arm()
                check = MotionCheck(cfg.turntable, cfg.trial.rate_hz)
            trial = LiveTrial(cfg, config_text, out, duration, ports, viewer=viewer, time_scale=time_scale,
                              motion_check=check,
                              on_progress=progress.update, stop_requested=stop_requested,
                              on_end=control.stop if control is not None else None,
                              source_done=(lambda: emulator.poll() is not None or (out / "emulator.json").exists())
                              if emulator else None)
            return trial, trial.run()
    except (TableError, LimitError, InterlockError) as exc:
        raise UsageError(str(exc)) from None
    finally:
        if viewer is not None:
            viewer.close()  # the trial closes it too; closing twice is harmless
        if control is not None:
            control.stop()
            if control.stop_error:
                print(f"hil: WARNING: could not confirm the turntable is off: {control.stop_error}", file=sys.stderr)
        if emulator is not None:
            stop_emulator(emulator)


def _speed(text: str) -> float | None:
    """``--speed``: a multiple of real time, None for ``max``."""
    from emulators.process import parse_speed

    try:
        return parse_speed(text)
    except ValueError as exc:
        raise UsageError(f"--speed: {exc}") from None


def _command_url(cfg, ports: dict | None) -> str | None:
    """The table's acl port: ``turntable.command_port``, where ``emulator`` means the emulated table's."""
    url = cfg.turntable.command_port
    if url == "emulator":
        if ports is None or "turntable_cmd" not in ports:
            raise UsageError("turntable.command_port: 'emulator' needs turntable.source: emulator")
        return ports["turntable_cmd"]
    return url


def cmd_replay(args: argparse.Namespace) -> int:
    from hil.replay import open_recording, recording_path, replay
    from hil.results import COMPLETED

    source_dir = recording_path(args.source).parent
    out = Path(args.out) if args.out else source_dir / "replay"
    recording, cfg = open_recording(args.source)
    viewer = _viewer(args, cfg, out, blocking=True)
    processor = replay(recording, cfg, viewer)
    if recording.truncated:
        print(f"hil: {args.source}: the recording ends inside a record (cut short); replayed up to it",
              file=sys.stderr)
    ended = recording.ended or ("early: the recording was cut short" if recording.truncated else COMPLETED)
    snapshots = processor.estimator.snapshots if processor.estimator is not None else []
    outcome = _finish(args, cfg, out, processor.result(), snapshots, recording.metadata["config"], ended)
    _close_viewer(viewer)
    return _exit_code(ended, outcome)


def cmd_report(args: argparse.Namespace) -> int:
    from hil.report import ReportError, write_report

    try:
        path = write_report(Path(args.dir))
    except ReportError as exc:
        raise UsageError(str(exc)) from None
    print(path)
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from emulators.simulation import Simulation
    from hil.config import load_config
    from hil.estimation.online import OnlineEstimator
    from hil.results import COMPLETED, StreamCounts, build_result

    cfg = load_config(args.config)
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(
        sim.truth.earth,
        sim.truth.geometry,
        solve_period=1.0 / cfg.estimator.solve_rate_hz,
        rank_tolerance=cfg.estimator.rank_tolerance,
    )
    out = _out_dir(args, cfg.trial.name, cfg.output.dir)
    viewer = _viewer(args, cfg, out, blocking=True)
    for batch in sim.batches():
        est.update_many(batch)
        if viewer is not None:
            viewer.log_table(batch.t, batch.angles)
    n = sim.samples
    result = build_result(cfg.trial.name, est, StreamCounts(n, n, n), list(cfg.imu.errors.accel_bias_ug))
    outcome = _finish(args, cfg, out, result, est.snapshots, Path(args.config).read_text(), COMPLETED)
    if viewer is not None:
        viewer.log_snapshots(est.snapshots)
    _close_viewer(viewer)
    return _exit_code(COMPLETED, outcome)


def cmd_estimate(args: argparse.Namespace) -> int:
    from hil.config import load_config
    from hil.csv_input import read_increments_csv
    from hil.estimation.online import OnlineEstimator
    from hil.frames import Earth, TableGeometry
    from hil.results import COMPLETED, StreamCounts, build_result

    cfg = load_config(args.config)
    batch = read_increments_csv(args.data)
    earth = Earth.from_degrees(cfg.site.latitude_deg, cfg.site.height_m)
    est = OnlineEstimator(
        earth,
        TableGeometry.from_config(cfg.turntable),
        solve_period=1.0 / cfg.estimator.solve_rate_hz,
        rank_tolerance=cfg.estimator.rank_tolerance,
        t0=batch.t0,
    )
    est.update_many(batch)
    n = len(batch)
    result = build_result(cfg.trial.name, est, StreamCounts(n, n if batch.angles is not None else 0, n))
    outcome = _finish(args, cfg, _out_dir(args, cfg.trial.name, cfg.output.dir), result, est.snapshots,
                      Path(args.config).read_text(), COMPLETED)
    return _exit_code(COMPLETED, outcome)


def cmd_decode(args: argparse.Namespace) -> int:
    from drivers.capture import CaptureError, decode_capture

    if args.dbc and args.protocol != "can-dbc":
        raise UsageError(f"--dbc {args.dbc}: only for protocol can-dbc, not {args.protocol}")
    try:
        counters = decode_capture(args.protocol, args.file, out_csv=args.out, dbc=args.dbc)
    except CaptureError as exc:
        raise UsageError(str(exc)) from None
    print(json.dumps(counters))
    return 0


def cmd_emulate(args: argparse.Namespace) -> int:
    from emulators.process import run_emulator
    from hil.config import load_config

    run_emulator(load_config(args.config), args.ports_file, _speed(args.speed), args.duration,
                 wait_readers=args.wait_readers)
    return 0


def _config_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", nargs="?", type=_config_path, default=DEFAULT_CONFIG,
                   help=f"trial YAML, a path or a shipped config's name (default {DEFAULT_CONFIG})")


def _viewer_options(p: argparse.ArgumentParser, default: str | None = None) -> None:
    from hil.viewer_modes import VIEWER_MODES, default_viewer_mode

    default = default or default_viewer_mode()
    p.add_argument("--viewer", choices=VIEWER_MODES, default=default,
                   help=f"Rerun viewer: native window, web viewer, .rrd file only, or nothing (default {default})")
    p.add_argument("--bind", default="127.0.0.1", help="address the web viewer listens on (default 127.0.0.1)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hil", description="Turntable IMU trials: emulate, acquire, estimate.",
                                     epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a trial: devices (or their emulators) -> recorder, estimator, viewer")
    _config_argument(p)
    p.add_argument("--out", help="output directory (default: output.dir or runs/NAME-TIME)")
    p.add_argument("--duration", type=float, help="seconds (default: trial.duration_s)")
    p.add_argument("--speed", default="1", help="emulated trials: X times real time, or 'max' (default 1)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    _viewer_options(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("replay", help="re-run the processing on a recording; same results as the live run")
    p.add_argument("source", help="a run directory (its recording.mcap) or a recording file")
    p.add_argument("--out", help="output directory (default: RUN_DIR/replay)")
    p.add_argument("--no-figures", action="store_true")
    _viewer_options(p)
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("simulate", help="emulator straight into the estimator, as fast as possible")
    _config_argument(p)
    p.add_argument("--out", help="output directory (default: output.dir or runs/NAME-TIME)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    _viewer_options(p, default="none")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("estimate", help="the estimator on a CSV of increments exported from other software")
    p.add_argument("data", help="CSV: t_s, dtheta_[xyz]_rad, dv_[xyz]_mps[, outer_deg, middle_deg, inner_deg]")
    p.add_argument("--config", required=True, type=_config_path, help="trial YAML (trial and site are enough)")
    p.add_argument("--out")
    p.add_argument("--no-figures", action="store_true")
    p.set_defaults(func=cmd_estimate)

    p = sub.add_parser("emulate", help="start the emulated devices on pseudo-terminals and print their ports")
    _config_argument(p)
    p.add_argument("--ports-file", type=Path, help="write the ports as JSON here once they are open")
    p.add_argument("--speed", default="1", help="X times real time, or 'max' (default 1)")
    p.add_argument("--duration", type=float, help="seconds of trial time (default: trial.duration_s)")
    p.add_argument("--wait-readers", action="store_true",
                   help="hold the pulse train until every port has a reader (default: stream at once, as hardware "
                        "does; frames nobody reads are lost and counted)")
    p.set_defaults(func=cmd_emulate)

    p = sub.add_parser("report", help="rebuild a trial's report.html from its outputs")
    p.add_argument("dir", help="a trial's output directory (result.json, series.csv, config.yaml)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("decode", help="decode a raw capture to CSV; counters as JSON on the last line")
    p.add_argument("protocol", help="kvh1750, xsens-mtdata2, tts1, can-dbc")
    p.add_argument("file", help="a raw byte dump, or a python-can .blf/.asc log for can-dbc")
    p.add_argument("--out", help="CSV to write (default: stdout is not used; counters only)")
    p.add_argument("--dbc", help="DBC file for can-dbc")
    p.set_defaults(func=cmd_decode)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # imported after parsing: --help needs none of them
    from drivers.transport import TransportError
    from hil.config import ConfigError
    from hil.csv_input import DataError

    try:
        return args.func(args)
    except (ConfigError, DataError, UsageError, TransportError) as exc:
        print(f"hil: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hil: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
