"""The live trial of ``hil run``: the devices (or their emulators, in their own process), the viewer, the
table under its controller's control and the :class:`~hil.trial.live.LiveTrial`; the table is sent Off, the
viewer closed and the emulator reaped on every way out, signals included."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path

from drivers.table_controller import InterlockError, LimitError, TableError
from emulators.process import parse_speed
from hil.config import Config
from hil.trial.live import LiveSettings, LiveTrial, TrialHooks
from hil.trial.outcome import TrialOutcome, TrialSetupError, emulated_truth
from hil.trial.rig import Rig, emulated
from hil.trial.stop_signals import StopSignals
from hil.trial.table_control import MotionCheck, check_controller, motion_needs
from hil.trial.viewer_feed import ViewerOptions, open_viewer, watched_chamber
from hil.viewer.console_progress import ConsoleProgress


# Given the open table control, the viewer (or None) and the open chamber controller (or None), starts the table and
# returns the trial's hooks for it: what watches it (``motion_check``, a listener of the pipeline), and for a trial
# the harness paces, ``finished`` and ``queue_items``; the default arms ``turntable.motion`` and checks it
# (:class:`MotionCheck`).
Commanded = Callable[[object, object, object], TrialHooks]


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
        trial, ended = _acquire(_Request(cfg, config_path, config_text, out, duration, speed, time_scale, viewer, quiet),
                                lambda: signals.received, commanded or functools.partial(_arm, cfg))
        outcome = TrialOutcome.of(trial.finished, cfg, config_text, out, ended, emulated_truth(cfg))
    return outcome, trial.viewer


@dataclasses.dataclass(frozen=True)
class _Request:
    """What :func:`run_live` was asked for."""

    cfg: Config
    config_path: Path
    config_text: str
    out: Path
    duration: float | None
    speed: str
    time_scale: float | None
    viewer: ViewerOptions
    quiet: bool


def _acquire(request: _Request, stop_requested, commanded: Commanded):
    """The rig (:class:`~hil.trial.rig.Rig`), the viewer and the trial; returns the finished trial and how it
    ended."""
    cfg, out, duration = request.cfg, request.out, request.duration
    viewer = None
    try:
        with Rig(cfg, request.config_path, out, request.speed, duration) as rig:
            viewer = open_viewer(request.viewer, cfg, out, blocking=False)
            chamber = watched_chamber(rig.chamber, cfg.environment.chamber.set_point_c, viewer) \
                if rig.chamber is not None else None  # its readings and set points to the viewer too
            with ConsoleProgress(duration, quiet=request.quiet) as progress:
                hooks = TrialHooks()
                if rig.table is not None:
                    hooks = dataclasses.replace(commanded(rig.table, viewer, chamber), on_end=rig.table.stop)
                hooks = dataclasses.replace(hooks, source_done=rig.source_done, on_progress=progress.update,
                                            on_warning=progress.warn, stop_requested=stop_requested)
                trial = LiveTrial(LiveSettings.of(cfg), request.config_text, out, duration, rig.links(), viewer,
                                  request.time_scale, hooks)
                return trial, trial.run()
    except (TableError, LimitError, InterlockError) as exc:
        raise TrialSetupError(str(exc)) from None
    finally:
        if viewer is not None:
            viewer.close()  # the trial closes it too; closing twice is harmless


def _check_motion(cfg: Config) -> None:
    """Refuse, before anything starts, a configured motion the controller cannot perform."""
    try:
        check_controller(cfg.turntable, *motion_needs(cfg.turntable))
    except TableError as exc:
        raise TrialSetupError(str(exc)) from None


def _arm(cfg: Config, control, viewer, chamber) -> TrialHooks:
    """``hil run``: the configured motion, checked against what the table reports."""
    control.arm()
    return TrialHooks(motion_check=MotionCheck(cfg.turntable, cfg.trial.rate_hz))
