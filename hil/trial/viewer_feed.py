"""The viewer of a trial: opened as ``--viewer`` asks, and fed the pipeline's snapshots, stream health,
gimbal angles and the IMU's temperature as it publishes them (:class:`~hil.pipeline.progress.Progress`), and the
chamber's readings and set points as the harness takes and sends them (:func:`watched_chamber`)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Protocol, TypeVar

import numpy as np

from hil.config import Config
from hil.estimation.online import Snapshot
from hil.frames import TableGeometry
from hil.inputs import InputError
from hil.outputs.judgement import Judgement
from hil.pipeline.health import FLAG_PREFIX
from hil.pipeline.progress import Health, Progress
from hil.samples import StreamCounts
from hil.trial.outcome import TrialSetupError, emulated_truth
from hil.units import HOUR, UG
from hil.viewer.modes import ViewerOptions
from hil.viewer.verdict import final_markdown
from hil.vocabulary import Stream


class Viewer(Protocol):
    """What a trial needs of a viewer (see :class:`hil.viewer.trial_viewer.TrialViewer`)."""

    mode: str
    url: str | None
    viewer_process: object | None

    def log_snapshot(self, snap: Snapshot) -> None: ...
    def log_snapshots(self, snaps: list[Snapshot]) -> None: ...
    def log_table(self, t: np.ndarray, angles: np.ndarray) -> None: ...
    def log_health(self, t: float, health: Health) -> None: ...
    def log_streams(self, counts: StreamCounts) -> None: ...
    def log_temperature(self, t: float, imu_c: float | None) -> None: ...
    def log_chamber(self, reading_c: float | None = None, set_point_c: float | None = None) -> None: ...
    def log_calibration_step(self, t: float, index: int, steps: list) -> None: ...
    def log_calibration_window(self, t: float, accel_ug: np.ndarray | None, gyro_dph: np.ndarray) -> None: ...
    def close(self) -> None: ...
    def end(self, verdict_markdown: str) -> None: ...
    def stop(self) -> None: ...


OwnView = TypeVar("OwnView")


def open_viewer(options: ViewerOptions, cfg: Config, out: Path, blocking: bool) -> Viewer | None:
    """The Rerun viewer the options ask for (None for ``none``); raises :class:`TrialSetupError` when it
    does not start."""
    if options.mode == "none":
        return None
    from hil.viewer.trial_viewer import (
        TrialViewer,  # rerun only when a viewer is asked for
    )

    truth = bias_truth(cfg)
    try:
        viewer = TrialViewer(options, out, geometry=TableGeometry.from_config(cfg.turntable), truth=truth,
                             limits=cfg.limits, recording_name=cfg.trial.name, blocking=blocking, verdict_at_end=True)
    except Exception as exc:  # noqa: BLE001 - whatever the viewer's process or port did, say it in one line
        raise TrialSetupError(f"--viewer {options.mode}: the viewer did not start: {exc}") from None
    if viewer.url:
        print(f"web viewer: {viewer.url}", file=sys.stderr)
    return viewer


def bias_truth(cfg: Config):
    """An emulated trial's accelerometer bias as its view draws it (a :class:`~hil.viewer.bias_view.BiasTruth`);
    None for a real device."""
    truth = emulated_truth(cfg)
    if truth is None:
        return None
    from hil.viewer.bias_view import BiasTruth

    return BiasTruth(np.array(truth["accel_bias_ug"]) * UG, np.array(truth["accel_drift_ug_per_h"]) * UG / HOUR)


def fixture_view(options: ViewerOptions, cfg: Config, out: Path):
    """The fixture's overview of a trial of several units, ``cfg`` its units config, saved in ``out`` (a
    :class:`~hil.viewer.fixture_view.FixtureView`, to open once the units' views are); None for ``none``."""
    if options.mode == "none":
        return None
    from hil.viewer.fixture_view import FixtureView  # rerun only when a viewer is asked for

    return FixtureView(options, out, cfg.trial.name)


def started_view(make: Callable[[], OwnView], mode: str) -> OwnView:
    """``make()``: a view with a recording of its own (:class:`hil.viewer.own_recording.OwnRecording`: a noise
    characterisation's, a plan's) in ``mode``, its web viewer's address printed; one that does not start is an
    :class:`~hil.inputs.InputError` naming ``--viewer``."""
    try:
        view = make()
    except Exception as exc:  # noqa: BLE001 - whatever the viewer's process or port did, say it in one line
        raise InputError(f"--viewer {mode}: the viewer did not start: {exc}") from None
    if view.url:
        print(f"web viewer: {view.url}", file=sys.stderr)
    return view


def show_verdict(viewer: Viewer | None, judged: Judgement) -> None:
    """Log the trial's verdict and judged measurements (those of report.html and junit.xml) and finish the .rrd."""
    if viewer is not None:
        viewer.end(final_markdown(judged))


def finish_viewer(viewer: Viewer | None) -> None:
    """Finish the .rrd; a served web viewer stays up until Ctrl-C. The view is then disconnected, all sent: a
    viewer that stops later finds nothing left to send."""
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


def flag_health(counts: StreamCounts) -> dict[str, dict[str, float]]:
    """The IMU's health flags as stream health (/health/flags): the samples it flagged invalid so far, ``invalid``,
    and each flag's, ``flag_<name>`` (those raised so far); none where the pipeline does not read the flags."""
    if "imu_invalid" not in counts.extra:
        return {}
    by_flag = counts.extra.get("imu_invalid_by_flag") or {}
    flags = {FLAG_PREFIX + name: n for name, n in by_flag.items()}
    return {Stream.IMU: {"invalid": counts.extra["imu_invalid"], **flags}}


class ChamberFeed:
    """A chamber's controller whose readings and set points also go to the viewer (``log_chamber``); every other
    call reaches the controller as it is."""

    def __init__(self, controller, viewer: Viewer) -> None:
        self.controller, self.viewer = controller, viewer

    def temperature_c(self) -> float:
        reading = self.controller.temperature_c()
        self.viewer.log_chamber(reading_c=reading)
        return reading

    def set_set_point_c(self, set_point_c: float) -> None:
        self.controller.set_set_point_c(set_point_c)
        self.viewer.log_chamber(set_point_c=set_point_c)

    def __getattr__(self, name: str):
        return getattr(self.controller, name)


def watched_chamber(controller, set_point_c: float | None, viewer: Viewer | None):
    """The open chamber ``controller`` (None: none) as the trial uses it: with a viewer, a :class:`ChamberFeed`, its
    ``set_point_c`` (sent when it was opened; None: none) logged at the start."""
    if controller is None or viewer is None:
        return controller
    if set_point_c is not None:
        viewer.log_chamber(set_point_c=set_point_c)
    return ChamberFeed(controller, viewer)


class ViewerFeed:
    """A listener of the pipeline logging to a viewer (or nowhere): the table angles of each block the estimator
    took and, with ``snapshots``, each new solution with the stream health (``live`` adds a live trial's
    figures to it, and the table's lag behind the IMU once the pipeline has measured it)."""

    def __init__(self, viewer: Viewer | None, live: Callable[[], Health] | None = None,
                 snapshots: bool = True) -> None:
        self.viewer = viewer
        self.live = live
        self.snapshots = snapshots

    def on_progress(self, progress: Progress) -> None:
        if self.viewer is None:
            return
        self.viewer.log_temperature(progress.trial_time, progress.temperature_c)
        for block in progress.taken:
            if len(block.table_t):
                self.viewer.log_table(block.table_t, block.table_angles)
        if not self.snapshots or not progress.snapshots:
            return
        live = {} if self.live is None else {stream: dict(values) for stream, values in self.live().items()}
        if progress.time_offset_s is not None:  # a live trial's check of the streams' lag
            live.setdefault("aligner", {})["table_lag_ms"] = 1e3 * progress.time_offset_s
        for stream, values in flag_health(progress.counts).items():
            live.setdefault(stream, {}).update(values)
        health = progress.with_live(live) if live else progress.health
        self.viewer.log_streams(progress.counts)
        for snap in progress.snapshots:
            self.viewer.log_snapshot(snap)
            self.viewer.log_health(snap.t, health)
