"""Rerun logging of a trial: bias convergence against its references, the verdict as it forms, observability,
alignment, the turntable in 3D, stream health.

:class:`TrialViewer` logs the estimator's snapshots, the gimbal angles and the stream counters to a
Rerun recording with the default blueprint (:mod:`hil.viewer.blueprint`: the 2019 paper's Figs. 2,
3/6 and 4/7, live), the bias per series (:mod:`hil.viewer.bias_view`) and, given the trial's limits, the
limits drawn and ``/verdict`` (:mod:`hil.viewer.judged_view`), at the end result.json's (:meth:`TrialViewer.end`).

Logging never blocks the caller: each call hands its data to one background thread that converts it
and passes it to the Rerun SDK (which writes from its own threads). When that thread falls behind, live
calls are dropped and counted (:attr:`TrialViewer.dropped`) rather than waited for; offline producers
(simulate, replay) pass ``blocking=True`` so nothing is lost, and a calibration's steps and windows (a few a
minute, each one a lab reads) are always waited for. The time series and the gimbal poses reach
the .rrd as one chunk per entity every ``FILE_FLUSH_S`` of trial time and a live view at once
(:mod:`hil.viewer.chunks`); the poses at ``TABLE_RATE_HZ``, the rest at the estimator's rate (1 Hz).

Viewer modes (:mod:`hil.viewer.modes`): ``spawn`` starts the native viewer, ``serve`` a web viewer
(the URL is printed), both as a child process (:mod:`hil.viewer.rerun_process`); ``save`` writes
``recording.rrd`` only; ``none`` logs nothing. ``spawn`` and ``serve`` write the .rrd too.
"""

from __future__ import annotations

import subprocess
import uuid
from collections.abc import Callable, Mapping
from datetime import timedelta
from pathlib import Path
from typing import Self

import numpy as np
import rerun as rr

from hil.config import ReportLimits
from hil.estimation.online import Snapshot
from hil.frames import TableGeometry
from hil.samples import StreamCounts
from hil.units import DEG, HOUR, UG
from hil.viewer.blueprint import (
    ANGLES,
    AXES,
    STREAM_COLORS,
    health_entity,
    health_series,
    log_series_styles,
)
from hil.viewer.bias_view import BiasTruth, bias_rows, log_bias_styles
from hil.viewer.calibration_view import CalibrationLog, calibration_views
from hil.viewer.chunks import Columns, Streams
from hil.viewer.judged_view import JudgedView, log_plan, log_verdict
from hil.viewer.log_jobs import LogJobs
from hil.viewer.modes import VIEWER_MODES, ViewerOptions
from hil.viewer.rerun_process import start_viewer, stop_served, telemetry_requested
from hil.viewer.scene import GIMBALS, axis_quaternions, log_cone, log_turntable
from hil.viewer.temperature_view import CHAMBER_READING, CHAMBER_SET_POINT, IMU, TemperatureLog

APPLICATION_ID = "turntable-hil"
RRD_NAME = "recording.rrd"
TABLE_RATE_HZ = 10.0  # gimbal poses in the 3D view: a step of 1 deg at 10 deg/s, a few pixels on screen
CONE_PERIOD_S = 10.0  # the reconstructed cone is redrawn at most this often (trial time)
FILE_FLUSH_S = 120.0  # the .rrd gets each time series as one chunk this often (trial time), the rest (wall time)


class TrialViewer:
    """Rerun logging of one trial; see the module docstring. All methods return at once."""

    def __init__(self, options: ViewerOptions, out_dir: Path, *, geometry: TableGeometry,
                 truth: BiasTruth | None = None, limits: ReportLimits | None = None, recording_name: str = "trial",
                 blocking: bool = False, verdict_at_end: bool = False) -> None:
        """The view ``options`` ask for (:class:`~hil.viewer.modes.ViewerOptions`: mode, bind address, layout, a
        running viewer to connect to, a plan's document) of a trial writing to ``out_dir``; ``truth``: an emulated
        trial's, drawn as the bias's reference; ``limits``: drawn, and judged in ``/verdict`` as the trial goes;
        ``blocking``: waits for room rather than drops (offline producers); ``verdict_at_end``: :meth:`close`
        waits for :meth:`end`'s verdict."""
        mode, layout, plan = options.mode, options.layout, options.plan
        if mode not in VIEWER_MODES:
            raise ValueError(f"viewer mode {mode!r}: choose one of {', '.join(VIEWER_MODES)}")
        self.mode = mode
        self.out_dir = Path(out_dir)
        self.geometry = geometry
        self._truth = truth
        self.truth_bias = None if truth is None else np.asarray(truth.bias, dtype=float)
        self.truth_drift = None if truth is None or truth.drift is None else np.asarray(truth.drift, dtype=float)
        self.blocking = blocking
        self.rrd_path: Path | None = None
        self.url: str | None = None  # the web viewer's address in serve mode
        self.grpc_url: str | None = None  # the running viewer's, where another trial's view can connect too
        self.viewer_process: subprocess.Popen | None = None
        self.dropped = 0  # calls not logged because the logging thread was behind
        self._jobs: LogJobs | None = None  # the logging thread
        self._closed = False
        self._next_table_tick = -np.inf
        self._next_cone_t = 0.0
        self._cone_pending: Snapshot | None = None  # the newest observable snapshot whose cone is not drawn
        self._ib0_logged = False
        self._t_latest = 0.0  # the latest trial time logged
        self._temperatures = TemperatureLog()
        self._file: rr.RecordingStream | None = None  # the .rrd's stream, its rows held FILE_FLUSH_S
        self._view: rr.RecordingStream | None = None  # the live view's (spawn, serve), its rows sent at once
        self._calibration: CalibrationLog | None = None
        self.verdict_at_end = verdict_at_end
        self._judged = JudgedView(limits, self.truth_bias, calibration_views() if layout == "calibration" else None,
                                  plan is not None)
        self._ended = False
        if mode == "none":
            self._rec = None
            return

        recording_id = uuid.uuid4()
        blueprint = self._judged.blueprint(None)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.rrd_path = self.out_dir / RRD_NAME
        self._file = recording_stream(recording_id, FILE_FLUSH_S)
        self._file.save(self.rrd_path)  # its blueprint at the end, with the converged estimate's ranges
        self._columns = [Columns(self._file, FILE_FLUSH_S)]
        if mode != "save" or options.connect is not None:  # connect: a viewer already running (a plan's), any mode
            self.viewer_process, self.grpc_url, self.url = (
                start_viewer(mode, options.bind, telemetry_requested()) if options.connect is None
                else (None, options.connect, None))
            self._view = recording_stream(recording_id)
            self._view.set_sinks(rr.GrpcSink(self.grpc_url), default_blueprint=blueprint)
            self._columns.append(Columns(self._view, 0.0))
        self._rec = Streams([self._file] + ([self._view] if self._view is not None else []))
        for rec in self._rec.recs:
            rec.send_recording_name(recording_name)
        self._health_series: dict[str, list[str]] = {}
        log_series_styles(self._rec, self.truth_bias is not None)
        log_bias_styles(self._rec, self.truth_bias is not None)
        log_plan(self._rec, plan)
        log_turntable(self._rec, geometry)
        self._jobs = LogJobs("rerun-logging", "the trial's view", self._due, self._finish)

    @property
    def error(self) -> BaseException | None:
        """The first error the logging thread met."""
        return self._jobs.error if self._jobs is not None else None

    # -- public API (called from the processing thread) --

    def log_snapshot(self, snap: Snapshot) -> None:
        """One estimator snapshot (live, at the display rate)."""
        self._submit(lambda: self._write_snapshots([snap]))

    def log_snapshots(self, snaps: list[Snapshot]) -> None:
        """Many snapshots at once, sent as columns (simulate, replay); waits for room, never drops."""
        if snaps:
            snaps = list(snaps)
            self._submit(lambda: self._write_snapshots(snaps), block=True)

    def log_table(self, t: np.ndarray, angles: np.ndarray) -> None:
        """Gimbal angles (N, 3) rad ordered (outer, middle, inner) at trial times t (N,) s, for the 3D view.

        Decimated to ``TABLE_RATE_HZ``."""
        if self._rec is None or len(t) == 0:
            return
        t = np.asarray(t, dtype=float)
        ticks = np.floor(t * TABLE_RATE_HZ + 1e-9)  # a sample on a tick belongs to it
        first_of_tick = np.empty(len(t), dtype=bool)
        first_of_tick[0] = True
        first_of_tick[1:] = ticks[1:] != ticks[:-1]
        keep = first_of_tick & (ticks >= self._next_table_tick)
        if not keep.any():
            return
        self._next_table_tick = ticks[keep][-1] + 1
        t_kept, angles_kept = t[keep], np.array(angles, dtype=float)[keep]
        self._submit(lambda: self._write_table(t_kept, angles_kept))

    def log_health(self, t: float, health: Mapping[str, Mapping[str, float]]) -> None:
        """Stream figures at trial time t: {stream: {metric: value}}, e.g. frames, corrupt, latency_p99_ms
        (:func:`hil.viewer.blueprint.health_entity`)."""
        if self._rec is None:
            return
        rows = [(stream, metric, float(value)) for stream, metrics in health.items() for metric, value in metrics.items()
                if value is not None]  # fmt: skip
        self._submit(lambda: self._write_health(float(t), rows))

    def log_streams(self, counts: StreamCounts) -> None:
        """result.json's stream counters so far (a :class:`~hil.samples.StreamCounts`), for the verdict so far."""
        if self._judged.verdict is not None:
            self._submit(lambda: self._judged.verdict.take_streams(counts.as_dict()))

    def log_temperature(self, t: float, imu_c: float | None) -> None:
        """The pipeline's progress at trial time t with the IMU's latest temperature (deg C, None: none reported),
        to ``/imu/temperature_c`` once a second of trial time (:mod:`hil.viewer.temperature_view`)."""
        if self._rec is not None and self._temperatures.imu_due(float(t), imu_c):
            self._submit(lambda: self._temperatures.write(self._rec, self._scalars, IMU, float(t), float(imu_c)))

    def log_chamber(self, reading_c: float | None = None, set_point_c: float | None = None) -> None:
        """The chamber's reading or set point (deg C) as the harness reads or sends it, at the trial time of the
        latest :meth:`log_temperature`."""
        t = self._temperatures.t_progress
        for path, value in ((CHAMBER_READING, reading_c), (CHAMBER_SET_POINT, set_point_c)):
            if value is not None:
                self._submit(lambda p=path, v=float(value): self._temperatures.write(self._rec, self._scalars, p, t, v))

    def log_calibration_step(self, t: float, index: int, steps: list) -> None:
        """Calibration step ``index`` (0-based) of ``steps`` (dwells and plateaus) commanded at trial time t
        (:mod:`hil.viewer.calibration_view`)."""
        steps = list(steps)
        self._submit(lambda: self._write_calibration(steps).step(float(t), index), block=True)

    def log_calibration_window(self, t: float, accel_ug: np.ndarray | None, gyro_dph: np.ndarray) -> None:
        """A calibration window's residuals before calibration at its end t: the accelerometers' (µg, a dwell;
        None for a plateau) and the gyros' (°/h)."""
        accel = None if accel_ug is None else np.array(accel_ug, dtype=float)
        gyro = np.array(gyro_dph, dtype=float)
        self._submit(lambda: self._calibration is not None and self._calibration.window(float(t), accel, gyro),
                     block=True)

    def close(self) -> None:
        """Log what is queued, flush and finish the .rrd (with ``verdict_at_end``, it waits for :meth:`end`, or
        :meth:`stop`, or the end of the process). A spawned viewer keeps running; a served one keeps serving until
        :meth:`stop` or the end of the process."""
        if self._rec is None or self._closed:
            return
        self._closed = True
        self._jobs.stop()
        if not self.verdict_at_end:
            self._end_file()
        else:
            self._file.flush()
        if self._view is not None:
            self._view.flush()

    def end(self, verdict_markdown: str) -> None:
        """Close, log the trial's verdict (``/verdict``: result.json's) at its last time and finish the .rrd."""
        if self._rec is None or self._ended:
            return
        self.close()
        self._jobs.run(lambda: log_verdict(self._rec, self._t_latest, verdict_markdown))
        self._end_file()
        if self._view is not None:
            self._view.flush()

    def stop(self) -> None:
        """Close, finish the .rrd and stop the web viewer server of ``serve`` mode."""
        self.close()
        if self._file is not None:
            self._end_file()
        if self._view is not None:
            self._view.disconnect()
        process, self.viewer_process = self.viewer_process, None
        stop_served(process, self.mode)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _end_file(self) -> None:
        """Flush and finish the .rrd (once)."""
        if not self._ended:
            self._ended = True
            self._file.flush()
            self._file.disconnect()  # the .rrd is complete

    # -- the logging thread --

    def _submit(self, job: Callable[[], None], block: bool | None = None) -> None:
        if self._rec is None or self._closed:
            return
        if not self._jobs.submit(job, self.blocking if block is None else block):
            self.dropped += 1

    def _due(self) -> None:
        """After each job: the rows due to each sink."""
        for columns in self._columns:
            self._jobs.run(lambda c=columns: c.due(self._t_latest))

    def _finish(self) -> None:
        """The last cone, the verdict so far, every row held, and the followed ranges in the .rrd's blueprint."""
        if self._cone_pending is not None:
            self._draw_cone(self._cone_pending)
        for columns in self._columns:
            columns.flush()
        self._judged.finish(self._rec, self._file, self._view)

    def _scalars(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        """Rows of a multi-series entity: values (N, K), one series per column; all-NaN rows left out."""
        values = np.asarray(values, dtype=float).reshape(len(t), -1)
        rows = ~np.all(np.isnan(values), axis=1)
        if not rows.any():
            return
        for columns in self._columns:
            columns.scalars(path, t[rows], values[rows])
        self._t_latest = max(self._t_latest, float(t[rows].max()))

    def _write_snapshots(self, snaps: list[Snapshot]) -> None:
        n = len(snaps)
        t = np.fromiter((s.t for s in snaps), float, n)
        nan3 = np.full(3, np.nan)
        for path, (t_rows, values) in bias_rows(snaps, self._truth).items():
            self._scalars(path, t_rows, values)
        sigma = np.array([s.full.bias_sigma if s.full.bias_sigma is not None else nan3 for s in snaps]) / UG
        self._scalars("sigma", t, sigma)
        drift = np.array([s.drift_check.drift if s.drift_check is not None else nan3 for s in snaps]) / UG * HOUR
        drift_sigma = np.array([s.drift_check.sigma if s.drift_check is not None else nan3 for s in snaps]) / UG * HOUR
        for k, a in enumerate(AXES):
            series = [drift[:, k], drift[:, k] - 3.0 * drift_sigma[:, k], drift[:, k] + 3.0 * drift_sigma[:, k]]
            if self.truth_drift is not None:
                series.append(np.where(np.isnan(drift[:, k]), np.nan, self.truth_drift[k] / UG * HOUR))
            self._scalars(f"drift/{a}", t, np.column_stack(series))
        ranks = [(s.full.observability.rank, s.gravity_only.observability.rank) for s in snaps]
        self._scalars("observability/rank", t, np.array(ranks, float))
        with np.errstate(divide="ignore", invalid="ignore"):
            condition = np.log10(np.array([s.full.observability.condition for s in snaps], float))
        self._scalars("observability/log10_condition", t, np.where(np.isfinite(condition), condition, np.nan))
        errors = {}
        for attr, size in (("error_method1", 3), ("error_method2", 3), ("error_theoretical", 2)):
            errors[attr] = np.array([getattr(s, attr) if getattr(s, attr) is not None else nan3[:size] for s in snaps])
        for k, angle in enumerate(ANGLES):
            columns = [errors["error_method1"][:, k], errors["error_method2"][:, k]]
            if k < 2:
                columns.append(errors["error_theoretical"][:, k])
            self._scalars(f"alignment/{angle}", t, np.column_stack(columns) / DEG)
        self._write_cones(snaps)
        self._judged.snapshots(snaps, sigma, self._scalars, self._rec, self._view)

    def _write_cones(self, snaps: list[Snapshot]) -> None:
        """The cone every ``CONE_PERIOD_S`` of trial time; the newest one not drawn is drawn at the end."""
        for s in snaps:
            if not (s.full.observable or s.gravity_only.observable):
                continue
            self._cone_pending = s
            if s.t >= self._next_cone_t:
                self._draw_cone(s)

    def _draw_cone(self, s: Snapshot) -> None:
        log_cone(self._rec, s.full if s.full.observable else s.gravity_only, s.t)
        self._next_cone_t = s.t + CONE_PERIOD_S
        self._cone_pending = None

    def _write_table(self, t: np.ndarray, angles: np.ndarray) -> None:
        if not self._ib0_logged:
            # i_b0 is the body frame at the start, fixed in inertial space: drawn at the first attitude C_b^n(0)
            start = self.geometry.attitude_matrix(angles[:1])[0][0]
            self._rec.log("world/ib0", rr.Transform3D(mat3x3=start), rr.TransformAxes3D(0.3), static=True)
            self._ib0_logged = True
        for path, k, axis in GIMBALS:
            for columns in self._columns:
                columns.quaternions(path, t, axis_quaternions(angles[:, k], axis))
        self._scalars("table/angles_deg", t, angles / DEG)

    def _write_calibration(self, steps: list) -> CalibrationLog:
        if self._calibration is None:
            self._calibration = CalibrationLog(self._rec, self.geometry, steps)
        return self._calibration

    def _write_health(self, t: float, rows: list[tuple[str, str, float]]) -> None:
        """One row per health entity, a series per stream and metric in order of appearance."""
        by_entity: dict[str, dict[str, float]] = {}
        for stream, metric, value in rows:
            by_entity.setdefault(health_entity(metric), {})[health_series(stream, metric)] = value
        for entity, values in by_entity.items():
            path = f"health/{entity}"
            series = self._health_series.setdefault(path, [])
            if any(name not in series for name in values):
                series.extend(name for name in values if name not in series)
                colors = [STREAM_COLORS[k % len(STREAM_COLORS)] for k in range(len(series))]
                self._rec.log(path, rr.SeriesLines(names=series, colors=colors), static=True)
            row = np.array([values.get(name, np.nan) for name in series])
            self._scalars(path, np.array([t]), row[None, :])


def recording_stream(recording_id: uuid.UUID, flush_s: float | None = None) -> rr.RecordingStream:
    """A stream of the trial's recording, on trial time alone; what it is logged (not sent as columns) is merged
    into chunks every ``flush_s`` s (None: rerun's default, 0.2 s)."""
    config = None if flush_s is None else rr.ChunkBatcherConfig(flush_tick=timedelta(seconds=flush_s))
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id, batcher_config=config)
    rr.set_log_time_enabled(False, recording=rec)
    rr.set_log_tick_enabled(False, recording=rec)
    return rec
