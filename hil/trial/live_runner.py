"""The live trial of ``hil run``: the devices (or their emulators, in their own process), the viewer, the
table under its controller's control and the :class:`~hil.trial.live.LiveTrial`; the table is sent Off, the
viewer closed and the emulator reaped on every way out, signals included."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path

from drivers.table_controller import InterlockError, LimitError, TableError
from emulators.process import EmulatorError, parse_speed, spawn_emulator, stop_emulator
from hil.config import Config
from hil.trial.chamber import open_chamber, release_chamber
from hil.trial.live import LiveTrial, TrialHooks
from hil.trial.outcome import TrialOutcome, TrialSetupError, emulated_truth
from hil.trial.stop_signals import StopSignals
from hil.trial.table_control import MotionCheck, TableControl, check_controller, motion_needs
from hil.trial.viewer_feed import ViewerOptions, open_viewer, watched_chamber
from hil.viewer.console_progress import ConsoleProgress
from hil.vocabulary import Port


def emulated(cfg: Config) -> bool:
    """Both devices emulated (a mixed config is refused)."""
    sources = {cfg.imu.source, cfg.turntable.source}
    if "emulator" in sources and sources != {"emulator"}:
        raise TrialSetupError("imu.source and turntable.source: emulate both devices or neither")
    return sources == {"emulator"}


# Given the open table control, the config, the viewer (or None) and the open chamber controller (or None), starts
# the table and returns the trial's hooks for it: what watches it (``motion_check``, a listener of the pipeline), and
# for a trial the harness paces, ``finished`` and ``queue_items``; the default arms ``turntable.motion`` and checks it
# (:class:`MotionCheck`).
Commanded = Callable[[object, Config, object, object], TrialHooks]


def run_live(cfg: Config, config_path: Path, out: Path, duration: float | None, speed: str,
             viewer: ViewerOptions, quiet: bool = False, commanded: Commanded | None = None
             ) -> tuple[TrialOutcome, object]:
    """Acquire, record and estimate until the trial ends; returns the outcome and the viewer (still open
    for a ``serve`` viewer to keep serving). ``commanded``: how the harness drives the table (see
    :data:`Commanded`)."""
    is_emulated = emulated(cfg)
    if commanded is None and cfg.turntable.command_port:
        _check_motion(cfg)
    duration = duration if duration is not None else cfg.trial.duration_s
    if is_emulated and duration is None:
        raise TrialSetupError("an emulated trial needs trial.duration_s or --duration")
    if is_emulated and cfg.imu.can is not None and cfg.imu.can.interface == "virtual":
        raise TrialSetupError("imu.can.interface: 'virtual' reaches only its own process, and the emulated devices "
                              "run in theirs; use udp_multicast (the default without an imu.can block)")
    time_scale = parse_speed(speed) if is_emulated else 1.0
    out.mkdir(parents=True, exist_ok=True)
    config_text = config_path.read_text()
    with StopSignals() as signals:
        trial, ended = _acquire(cfg, config_path, config_text, out, duration, speed, time_scale, viewer, quiet,
                                lambda: signals.received, commanded or _arm)
        outcome = TrialOutcome.of(trial.finished, cfg, config_text, out, ended, emulated_truth(cfg))
    return outcome, trial.viewer


def _acquire(cfg: Config, config_path: Path, config_text: str, out: Path, duration: float | None, speed: str,
             time_scale: float | None, options: ViewerOptions, quiet: bool, stop_requested, commanded: Commanded):
    """Emulator (if emulated), viewer, table control and the trial; returns the finished trial and how it ended."""
    emulator, ports, control, viewer, chamber = None, None, None, None, None
    try:
        if emulated(cfg):
            try:
                emulator, ports = spawn_emulator(config_path, out / "ports.json", speed, duration,
                                                 stats_file=out / "emulator.json", log_file=out / "emulator.log",
                                                 hold=True)
            except EmulatorError as exc:
                raise TrialSetupError(f"{config_path}: {exc}") from None
        chamber = open_chamber(cfg.environment.chamber, ports)  # before the table moves
        viewer = open_viewer(options, cfg, out, blocking=False)
        if chamber is not None:  # its readings and set points to the viewer too
            chamber = watched_chamber(chamber, cfg.environment.chamber.set_point_c, viewer)
        url = command_url(cfg, ports)
        with ConsoleProgress(duration, quiet=quiet) as progress:
            hooks = TrialHooks()
            if url is not None:
                control = TableControl(url, cfg.turntable)
                control.open()
                hooks = dataclasses.replace(commanded(control, cfg, viewer, chamber), on_end=control.stop)
            if emulator is not None:
                hooks = dataclasses.replace(hooks, source_done=lambda: emulator.poll() is not None
                                            or (out / "emulator.json").exists())
            hooks = dataclasses.replace(hooks, on_progress=progress.update, on_warning=progress.warn,
                                        stop_requested=stop_requested)
            trial = LiveTrial(cfg, config_text, out, duration, ports, viewer, time_scale, hooks)
            return trial, trial.run()
    except (TableError, LimitError, InterlockError) as exc:
        raise TrialSetupError(str(exc)) from None
    finally:
        if viewer is not None:
            viewer.close()  # the trial closes it too; closing twice is harmless
        if control is not None:
            control.stop()
            if control.stop_error:
                print(f"hil: WARNING: could not confirm the turntable is off: {control.stop_error}", file=sys.stderr)
        if chamber is not None:  # after the table is off
            release_chamber(chamber, cfg.environment.chamber)
        if emulator is not None:
            stop_emulator(emulator)


def _check_motion(cfg: Config) -> None:
    """Refuse, before anything starts, a configured motion the controller cannot perform."""
    try:
        check_controller(cfg.turntable, *motion_needs(cfg.turntable))
    except TableError as exc:
        raise TrialSetupError(str(exc)) from None


def _arm(control, cfg: Config, viewer, chamber) -> TrialHooks:
    """``hil run``: the configured motion, checked against what the table reports."""
    control.arm()
    return TrialHooks(motion_check=MotionCheck(cfg.turntable, cfg.trial.rate_hz))


def command_url(cfg: Config, ports: dict | None) -> str | None:
    """The table's command port: ``turntable.command_port``, where ``emulator`` means the emulated table's."""
    url = cfg.turntable.command_port
    if url == "emulator":
        if ports is None or Port.TABLE_CMD not in ports:
            raise TrialSetupError("turntable.command_port: 'emulator' needs turntable.source: emulator")
        return ports[Port.TABLE_CMD]
    return url
