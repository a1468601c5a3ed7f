"""Rerun views of a trial: bias convergence, observability, alignment, the turntable in 3D, stream health.

:class:`TrialViewer` logs the estimator's snapshots, the gimbal angles and the stream counters to a
Rerun recording with a default blueprint (the 2019 paper's Figs. 2, 3/6 and 4/7, live). The timeline
is ``trial_time``: seconds since the start of the trial, the clock of ``Snapshot.t``. Entity paths
and units are listed in docs/viewer.md.

Logging never blocks the caller: each call hands its data to one background thread that converts it
and passes it to the Rerun SDK (which batches and writes from its own threads). When that thread
falls behind, live calls are dropped and counted (:attr:`TrialViewer.dropped`) rather than waited
for; offline producers (simulate, replay) pass ``blocking=True`` so nothing is lost.

Viewer modes: ``spawn`` starts the native viewer, ``serve`` a web viewer (the URL is printed), both
as a child ``rerun`` process bound to 127.0.0.1 unless another bind address is given; ``save``
writes ``recording.rrd`` only; ``none`` logs nothing. ``spawn`` and ``serve`` write the .rrd too.
Rerun's usage analytics are off in the viewers started here unless the caller turns them on
(``telemetry=True`` or ``HIL_RERUN_TELEMETRY=1``).
"""

from __future__ import annotations

import atexit
import logging
import os
import queue
import shutil
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Self
from urllib.parse import quote

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hil.estimation.online import Snapshot
from hil.frames import EARTH_RATE, TableGeometry
from hil.units import DEG, UG
from hil.viewer.modes import VIEWER_MODES

log = logging.getLogger(__name__)

APPLICATION_ID = "turntable-hil"
TIMELINE = "trial_time"
RRD_NAME = "recording.rrd"
TELEMETRY_ENV = "HIL_RERUN_TELEMETRY"
TABLE_RATE_HZ = 20.0  # gimbal angles in the 3D view; the viewer draws at display rate anyway
CONE_PERIOD_S = 10.0  # the reconstructed cone is redrawn at most this often (trial time)
CONE_POINTS = 72
CONE_LENGTH = 1.5  # scene units (the outer gimbal has radius 1)
QUEUE_ITEMS = 1024
SMALL_BATCH = 8  # rows up to this many are logged one by one (merged by the SDK), more as columns
GIMBALS = (("world/table/outer", 0, 2), ("world/table/outer/middle", 1, 0), ("world/table/outer/middle/inner", 2, 1))

AXES = ("x", "y", "z")
ANGLES = ("pitch", "roll", "yaw")
HEALTH_VIEWS = (("rate_hz", "frame rate (Hz)"), ("frames", "frames"), ("dropped", "dropped frames"),
                ("corrupt", "corrupt frames (CRC, framing)"), ("latency_ms", "latency (ms)"),
                ("sync_offset_ms", "sync offset (ms)"))

_AXIS_COLORS = {"x": (228, 26, 28), "y": (77, 175, 74), "z": (55, 126, 184)}
_BAND = 0.55  # band lines: the axis colour mixed with grey
_TRUTH = (255, 170, 0)
_METHOD_COLORS = {"method1": (230, 85, 13), "method2": (49, 163, 84), "theoretical": (170, 170, 170)}
_METHOD_NAMES = {"method1": "method 1", "method2": "method 2", "theoretical": "theoretical"}
_STREAM_COLORS = ((55, 126, 184), (228, 26, 28), (77, 175, 74), (152, 78, 163), (255, 127, 0))


def telemetry_requested() -> bool:
    """Whether the user turned Rerun's usage analytics on (``HIL_RERUN_TELEMETRY=1``)."""
    return os.environ.get(TELEMETRY_ENV, "").strip().lower() in ("1", "true", "yes", "on")


# --- blueprint -----------------------------------------------------------------------------------


def _band_color(axis: str) -> tuple[int, int, int]:
    return tuple(int(_BAND * c + (1 - _BAND) * 128) for c in _AXIS_COLORS[axis])


def default_blueprint() -> rrb.Blueprint:
    """The trial layout: bias (Fig. 3/6) | observability and alignment (Figs. 2, 4/7) | 3D and stream health."""
    bias = [
        rrb.TimeSeriesView(origin=f"/bias/{a}", name=f"bias {a} (µg)", plot_legend=rrb.PlotLegend(visible=a == "x"))
        for a in AXES
    ]
    bias.append(rrb.TimeSeriesView(origin="/sigma", name="bias 1σ (µg)"))
    observability = [
        rrb.TimeSeriesView(origin="/observability/rank", name="scaled Gram rank", axis_y=rrb.ScalarAxis(range=(0.0, 13.0))),
        rrb.TimeSeriesView(origin="/observability/log10_condition", name="log10 condition number",
                           plot_legend=rrb.PlotLegend(visible=False)),
    ]  # fmt: skip
    alignment = [
        rrb.TimeSeriesView(origin=f"/alignment/{angle}", name=f"{angle} error (deg)",
                           plot_legend=rrb.PlotLegend(visible=angle == "pitch"))
        for angle in ANGLES
    ]  # fmt: skip
    health = rrb.Grid(
        *(rrb.TimeSeriesView(origin=f"/health/{metric}", name=title) for metric, title in HEALTH_VIEWS),
        grid_columns=2,
        name="stream health",
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(*bias, name="accelerometer bias"),
            rrb.Vertical(*observability, *alignment, name="observability and alignment"),
            rrb.Vertical(
                rrb.Spatial3DView(origin="/world", name="turntable and apparent gravity in i_b0"),
                health,
                row_shares=[3, 2],
            ),
            column_shares=[1, 1, 1],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
    )


# --- geometry of the 3D scene --------------------------------------------------------------------


def _circle(radius: float, plane: str, n: int = 64) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, n + 1)
    c, s = radius * np.cos(a), radius * np.sin(a)
    z = np.zeros_like(a)
    return {"xy": np.column_stack((c, s, z)), "xz": np.column_stack((c, z, s)), "yz": np.column_stack((z, c, s))}[plane]


def _axis_quaternions(angles: np.ndarray, axis: int) -> np.ndarray:
    """Quaternions (x, y, z, w) of rotations by ``angles`` about one coordinate axis, (N, 4)."""
    q = np.zeros((len(angles), 4))
    q[:, axis] = np.sin(0.5 * angles)
    q[:, 3] = np.cos(0.5 * angles)
    return q


def cone_strips(solution, t: float, points: int = CONE_POINTS) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The reconstructed apparent-gravity cone in i_b0 (2014 eq. 17), unit length ``CONE_LENGTH``.

    Returns the wireframe of one sidereal day of the model (rim and generatrices), the arc swept
    during the trial so far, and the vector at ``t``.
    """
    day = 2.0 * np.pi / EARTH_RATE
    f = solution.apparent_gravity(np.linspace(0.0, day, points + 1))
    scale = CONE_LENGTH / np.linalg.norm(f[0])
    rim = f * scale
    generatrices = [np.vstack((np.zeros(3), rim[k])) for k in range(0, points, points // 8)]
    arc = solution.apparent_gravity(np.linspace(0.0, max(t, 0.0), 32)) * scale
    return [rim, *generatrices], arc, arc[-1]


# --- the viewer ----------------------------------------------------------------------------------


class TrialViewer:
    """Rerun logging of one trial; see the module docstring. All methods return at once."""

    def __init__(
        self,
        mode: str,
        out_dir: Path,
        *,
        geometry: TableGeometry,
        truth_bias: np.ndarray | None = None,
        bind: str = "127.0.0.1",
        recording_name: str = "trial",
        blocking: bool = False,
        telemetry: bool | None = None,
        table_rate_hz: float = TABLE_RATE_HZ,
    ) -> None:
        if mode not in VIEWER_MODES:
            raise ValueError(f"viewer mode {mode!r}: choose one of {', '.join(VIEWER_MODES)}")
        self.mode = mode
        self.out_dir = Path(out_dir)
        self.geometry = geometry
        self.truth_bias = None if truth_bias is None else np.asarray(truth_bias, dtype=float)
        self.bind = bind
        self.blocking = blocking
        self.table_rate_hz = table_rate_hz
        self.telemetry = telemetry_requested() if telemetry is None else telemetry
        self.rrd_path: Path | None = None
        self.url: str | None = None  # the web viewer's address in serve mode
        self.viewer_process: subprocess.Popen | None = None
        self.dropped = 0  # calls not logged because the logging thread was behind
        self.error: BaseException | None = None  # the first error the logging thread met
        self._closed = False
        self._next_table_tick = -np.inf
        self._next_cone_t = 0.0
        self._ib0_logged = False
        if mode == "none":
            self._rec = None
            return

        self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        rr.set_log_time_enabled(False, recording=self._rec)
        rr.set_log_tick_enabled(False, recording=self._rec)
        blueprint = default_blueprint()
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.rrd_path = self.out_dir / RRD_NAME
        if mode == "save":
            self._rec.save(self.rrd_path, default_blueprint=blueprint)
        else:
            grpc_url = self._start_viewer()
            self._rec.set_sinks(rr.GrpcSink(grpc_url), rr.FileSink(self.rrd_path), default_blueprint=blueprint)
        self._rec.send_recording_name(recording_name)
        self._log_static()
        self._queue: queue.Queue[Callable[[], None] | None] = queue.Queue(QUEUE_ITEMS)
        self._worker = threading.Thread(target=self._work, name="rerun-logging", daemon=True)
        self._worker.start()

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

        Decimated to ``table_rate_hz``."""
        if self._rec is None or len(t) == 0:
            return
        t = np.asarray(t, dtype=float)
        ticks = np.floor(t * self.table_rate_hz + 1e-9)  # a sample on a tick belongs to it
        first_of_tick = np.empty(len(t), dtype=bool)
        first_of_tick[0] = True
        first_of_tick[1:] = ticks[1:] != ticks[:-1]
        keep = first_of_tick & (ticks >= self._next_table_tick)
        if not keep.any():
            return
        self._next_table_tick = ticks[keep][-1] + 1
        t_kept, angles_kept = t[keep], np.array(angles, dtype=float)[keep]
        self._submit(lambda: self._write_table(t_kept, angles_kept))

    def log_health(self, t: float, health: dict[str, dict[str, float]]) -> None:
        """Stream counters at trial time t: {stream: {metric: value}}, e.g. rate_hz, dropped, latency_ms."""
        if self._rec is None:
            return
        rows = [(stream, metric, float(value)) for stream, metrics in health.items() for metric, value in metrics.items()
                if value is not None]  # fmt: skip
        self._submit(lambda: self._write_health(float(t), rows))

    def close(self) -> None:
        """Log what is queued, flush and finish the .rrd. A spawned viewer keeps running; a served one
        keeps serving until :meth:`stop` or the end of the process."""
        if self._rec is None or self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._worker.join()
        self._rec.flush()
        if self.mode == "save":
            self._rec.disconnect()
        if self.error is not None:
            log.warning("Rerun logging failed: %s", self.error)

    def stop(self) -> None:
        """Close, and stop the web viewer server of ``serve`` mode."""
        self.close()
        if self._rec is not None and self.mode != "save":
            self._rec.disconnect()
        process, self.viewer_process = self.viewer_process, None
        if process is not None and self.mode == "serve" and process.poll() is None:
            process.terminate()
            try:
                process.wait(5.0)
            except subprocess.TimeoutExpired:
                process.kill()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- the logging thread --

    def _submit(self, job: Callable[[], None], block: bool | None = None) -> None:
        if self._rec is None or self._closed:
            return
        try:
            self._queue.put(job, block=self.blocking if block is None else block)
        except queue.Full:
            self.dropped += 1

    def _work(self) -> None:
        while (job := self._queue.get()) is not None:
            try:
                job()
            except Exception as exc:  # noqa: BLE001 - logging must never stop a trial
                if self.error is None:
                    self.error = exc
                    log.warning("Rerun logging error (further errors not reported): %s", exc)

    def _scalars(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        """Rows of a multi-series entity: values (N, K), one series per column; all-NaN rows left out.

        A few rows go through ``log`` (the SDK merges them into large chunks), many through
        ``send_columns``; one Rerun call costs tens of microseconds either way, hence few entities."""
        values = np.asarray(values, dtype=float).reshape(len(t), -1)
        rows = ~np.all(np.isnan(values), axis=1)
        if not rows.any():
            return
        t, values = t[rows], values[rows]
        if len(t) <= SMALL_BATCH:
            for ti, row in zip(t, values):
                self._rec.set_time(TIMELINE, duration=float(ti))
                self._rec.log(path, rr.Scalars(row))
        else:
            columns = rr.Scalars.columns(scalars=values).partition([values.shape[1]] * len(t))
            self._rec.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=columns)

    def _write_snapshots(self, snaps: list[Snapshot]) -> None:
        n = len(snaps)
        t = np.fromiter((s.t for s in snaps), float, n)
        nan3 = np.full(3, np.nan)
        bias = np.array([s.full.bias if s.full.bias is not None else nan3 for s in snaps]) / UG
        sigma = np.array([s.full.bias_sigma if s.full.bias_sigma is not None else nan3 for s in snaps]) / UG
        for k, a in enumerate(AXES):
            series = [bias[:, k], bias[:, k] - 3.0 * sigma[:, k], bias[:, k] + 3.0 * sigma[:, k]]
            if self.truth_bias is not None:
                series.append(np.where(np.isnan(bias[:, k]), np.nan, self.truth_bias[k] / UG))
            self._scalars(f"bias/{a}", t, np.column_stack(series))
        self._scalars("sigma", t, sigma)
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

    def _write_cones(self, snaps: list[Snapshot]) -> None:
        for i, s in enumerate(snaps):
            solution = s.full if s.full.observable else s.gravity_only
            if s.t < self._next_cone_t and i != len(snaps) - 1 or not solution.observable:
                continue
            self._next_cone_t = s.t + CONE_PERIOD_S
            wireframe, arc, now = cone_strips(solution, s.t)
            self._rec.set_time(TIMELINE, duration=s.t)
            self._rec.log("world/ib0/cone", rr.LineStrips3D(wireframe, radii=0.004, colors=(120, 120, 160)))
            self._rec.log("world/ib0/trial_arc", rr.LineStrips3D([arc], radii=0.015, colors=_TRUTH))
            self._rec.log("world/ib0/apparent_gravity", rr.Arrows3D(vectors=[now], radii=0.012, colors=(240, 240, 240)))

    def _write_table(self, t: np.ndarray, angles: np.ndarray) -> None:
        if not self._ib0_logged:
            # i_b0 is the body frame at the start, fixed in inertial space: drawn at the first attitude C_b^n(0)
            start = self.geometry.attitude_matrix(angles[:1])[0][0]
            self._rec.log("world/ib0", rr.Transform3D(mat3x3=start), rr.TransformAxes3D(0.3), static=True)
            self._ib0_logged = True
        for path, k, axis in GIMBALS:
            q = _axis_quaternions(angles[:, k], axis)
            if len(t) <= SMALL_BATCH:
                for ti, qi in zip(t, q):
                    self._rec.set_time(TIMELINE, duration=float(ti))
                    self._rec.log(path, rr.Transform3D(quaternion=qi))
            else:
                self._rec.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=t)],
                                       columns=rr.Transform3D.columns(quaternion=q))  # fmt: skip
        self._scalars("table/angles_deg", t, angles / DEG)

    def _write_health(self, t: float, rows: list[tuple[str, str, float]]) -> None:
        by_metric: dict[str, dict[str, float]] = {}
        for stream, metric, value in rows:
            by_metric.setdefault(metric, {})[stream] = value
        for metric, values in by_metric.items():
            path = f"health/{rr.escape_entity_path_part(metric)}"
            streams = self._health_streams.setdefault(path, [])
            if any(stream not in streams for stream in values):
                streams.extend(stream for stream in values if stream not in streams)
                colors = [_STREAM_COLORS[k % len(_STREAM_COLORS)] for k in range(len(streams))]
                self._rec.log(path, rr.SeriesLines(names=streams, colors=colors), static=True)
            row = np.array([values.get(stream, np.nan) for stream in streams])
            self._scalars(path, np.array([t]), row[None, :])

    # -- setup --

    def _log_static(self) -> None:
        rec = self._rec
        self._health_streams: dict[str, list[str]] = {}
        for a in AXES:
            names, colors, widths = ["estimate", "−3σ", "+3σ"], [_AXIS_COLORS[a], _band_color(a), _band_color(a)], [2, 1, 1]
            if self.truth_bias is not None:
                names, colors, widths = names + ["truth"], colors + [_TRUTH], widths + [1.5]
            rec.log(f"bias/{a}", rr.SeriesLines(names=names, colors=colors, widths=widths), static=True)
        rec.log("sigma", rr.SeriesLines(names=list(AXES), colors=[_AXIS_COLORS[a] for a in AXES]), static=True)
        rec.log("observability/rank", rr.SeriesLines(names=["12-state (with bias)", "9-state (method 1)"],
                                                     colors=[(55, 126, 184), (230, 85, 13)]), static=True)  # fmt: skip
        rec.log("observability/log10_condition", rr.SeriesLines(names="log10 cond", colors=(55, 126, 184)), static=True)
        for angle in ANGLES:
            methods = ("method1", "method2") if angle == "yaw" else ("method1", "method2", "theoretical")
            rec.log(f"alignment/{angle}", rr.SeriesLines(names=[_METHOD_NAMES[m] for m in methods],
                                                         colors=[_METHOD_COLORS[m] for m in methods]), static=True)  # fmt: skip
        rec.log("table/angles_deg", rr.SeriesLines(names=["outer", "middle", "inner"],
                                                   colors=[(55, 126, 184), (77, 175, 74), (228, 26, 28)]), static=True)  # fmt: skip

        # the turntable: base, three gimbal rings with their axles, the IMU case on the inner gimbal
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log("world/table", rr.Transform3D(mat3x3=self.geometry.table_to_n.as_matrix()), static=True)
        rec.log("world/table/base", rr.Boxes3D(centers=[0, 0, -1.28], half_sizes=[0.7, 0.7, 0.06],
                                               colors=(90, 90, 90), fill_mode="solid"), static=True)  # fmt: skip
        rec.log("world/table/shaft", rr.LineStrips3D([[[0, 0, -1.22], [0, 0, -1.0]]], radii=0.03, colors=(150, 150, 150)),
                static=True)  # fmt: skip
        for path, strips, color in (
            ("world/table/outer/ring", [_circle(1.0, "xz")], (55, 126, 184)),
            ("world/table/outer/middle/ring", [_circle(0.8, "xy"), [[0.8, 0, 0], [1.0, 0, 0]], [[-0.8, 0, 0], [-1.0, 0, 0]]],
             (77, 175, 74)),
            ("world/table/outer/middle/inner/ring", [_circle(0.6, "yz"), [[0, 0.6, 0], [0, 0.8, 0]], [[0, -0.6, 0], [0, -0.8, 0]]],
             (228, 26, 28)),
        ):  # fmt: skip
            rec.log(path, rr.LineStrips3D(strips, radii=0.02, colors=color), static=True)
        imu = "world/table/outer/middle/inner/imu"
        rec.log(imu, rr.Transform3D(mat3x3=self.geometry.body_to_mount.as_matrix()), rr.TransformAxes3D(0.45),
                static=True)  # fmt: skip
        rec.log(f"{imu}/case", rr.Boxes3D(half_sizes=[0.22, 0.18, 0.1], colors=(200, 200, 200), fill_mode="solid",
                                         labels="IMU"), static=True)  # fmt: skip

    def _start_viewer(self) -> str:
        """Start ``rerun`` (native or web) as a child process bound to ``bind``; returns its gRPC URL."""
        exe = _rerun_executable()
        grpc_port = _free_port(self.bind, 9876)
        args = [exe, "--bind", self.bind, "--port", str(grpc_port), "--memory-limit", "50%"]
        if self.mode == "serve":
            web_port = _free_port(self.bind, 9090, exclude=grpc_port)
            args += ["--serve-web", "--web-viewer-port", str(web_port), "--server-memory-limit", "25%"]
        else:
            args += ["--expect-data-soon"]
        env = dict(os.environ)
        if not self.telemetry:
            # rerun 0.41 has no switch for this other than its config file (`rerun analytics disable`);
            # its analytics pipeline stays off when CI is set, so the child gets it
            env["CI"] = env.get("CI") or "1"
        process = subprocess.Popen(
            args, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            start_new_session=self.mode == "spawn",
        )  # fmt: skip
        local, public = _hosts(self.bind)
        if not _wait_port(local, grpc_port, process, timeout=15.0):
            err = process.stderr.read().decode(errors="replace")[-2000:] if process.poll() is not None else ""
            process.kill()
            hint = " (no display? use --viewer serve or save)" if self.mode == "spawn" else ""
            raise RuntimeError(f"the Rerun viewer did not start{hint}: {' '.join(args)}\n{err}".rstrip())
        if self.mode == "serve":
            threading.Thread(target=_drain, args=(process.stderr,), daemon=True).start()
            atexit.register(_terminate, process)
            grpc_public = f"rerun+http://{_url_host(public)}:{grpc_port}/proxy"
            self.url = f"http://{_url_host(public)}:{web_port}/?url={quote(grpc_public, safe='')}"
            print(f"Rerun web viewer: {self.url}", file=sys.stderr, flush=True)
        else:
            process.stderr.close()
        self.viewer_process = process
        return f"rerun+http://{_url_host(local)}:{grpc_port}/proxy"


def _rerun_executable() -> str:
    """The ``rerun`` binary of the installed rerun-sdk (the one whose version matches the SDK)."""
    try:
        import rerun_cli

        path = Path(rerun_cli.__file__).parent / "rerun"
        if path.exists():
            return str(path)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if found is None:
        raise RuntimeError("the rerun viewer executable was not found: reinstall rerun-sdk (pip install rerun-sdk)")
    return found


def _hosts(bind: str) -> tuple[str, str]:
    """(address this process connects to, host name a browser is given) for a server bound to ``bind``."""
    if bind in ("0.0.0.0", ""):
        return "127.0.0.1", socket.gethostname()
    if bind == "::":
        return "::1", socket.gethostname()
    return bind, bind


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def _free_port(bind: str, preferred: int, exclude: int | None = None) -> int:
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    for port in (preferred, 0):
        if port and port == exclude:
            continue
        with socket.socket(family, socket.SOCK_STREAM) as s:
            try:
                s.bind((bind, port))
            except OSError:
                continue
            return s.getsockname()[1]
    raise RuntimeError(f"no free TCP port on {bind}")


def _wait_port(host: str, port: int, process: subprocess.Popen, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            return False
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return True
        except OSError:
            time.sleep(0.1)
    return False


def _drain(stream) -> None:
    for _ in iter(lambda: stream.read(4096), b""):
        pass


def _terminate(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
