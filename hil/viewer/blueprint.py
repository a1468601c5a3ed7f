"""The Rerun layout of a trial: the default blueprint and the styles of its time series.

The timeline is ``trial_time``: seconds since the start of the trial, the clock of ``Snapshot.t``.
Entity paths and units are listed in docs/viewer.md.
"""

from __future__ import annotations

import rerun as rr
import rerun.blueprint as rrb

from hil.pipeline.health import FLAG_PREFIX
from hil.viewer.temperature_view import TEMPERATURES

TIMELINE = "trial_time"
AXES = ("x", "y", "z")
ANGLES = ("pitch", "roll", "yaw")
# the stream-health figures (the pipeline's and a live trial's) by entity: /health/<entity>, a series per stream
HEALTH_GROUPS = {"frames": "frames", "aligned": "frames", "corrupt": "faults", "missing": "faults",
                 "outages": "faults", "filled": "faults", "bridged": "faults", "without_angles": "faults",
                 "queue": "queue", "table_lag_ms": "sync_ms", "invalid": "flags"}  # fmt: skip
HEALTH_VIEWS = (("frames", "frames decoded, samples aligned"),
                ("faults", "corrupt, missing, outages; filled, bridged, without angles"),
                ("flags", "samples the IMU flags invalid, in all and by flag"),
                ("latency_ms", "latency and age, p50 / p99 / max (ms)"), ("queue", "queue (items)"),
                ("sync_ms", "table's lag behind the IMU (ms)"))

FOLLOW_SIGMAS = 5.0  # the followed bias view spans the latest estimate ± this many sigma (hil.viewer.bias_view)
LIMIT_COLOR = (130, 0, 170)  # purple: none of the axes, the truth or the reference
AXIS_COLORS = {"x": (228, 26, 28), "y": (77, 175, 74), "z": (55, 126, 184)}
_BAND = 0.55  # band lines: the axis colour mixed with grey
TRUTH_COLOR = (255, 170, 0)
_METHOD_COLORS = {"method1": (230, 85, 13), "method2": (49, 163, 84), "theoretical": (170, 170, 170)}
_METHOD_NAMES = {"method1": "method 1", "method2": "method 2", "theoretical": "theoretical"}
STREAM_COLORS = ((55, 126, 184), (228, 26, 28), (77, 175, 74), (152, 78, 163), (255, 127, 0))


def health_entity(metric: str) -> str:
    """The health entity of a metric: its group of ``HEALTH_GROUPS`` (a health flag's, ``flag_<name>``: ``flags``),
    else ``latency_ms`` for a figure in ms (``*_ms``), else one of its own (its name, escaped)."""
    if metric in HEALTH_GROUPS or metric.startswith(FLAG_PREFIX):
        return HEALTH_GROUPS.get(metric, "flags")
    return "latency_ms" if metric.endswith("_ms") else rr.escape_entity_path_part(metric)


def health_series(stream: str, metric: str) -> str:
    """The name of one stream's metric in its entity: ``imu corrupt``, ``aligner latency p99``."""
    return f"{stream} {metric.removesuffix('_ms').replace('_', ' ')}"


def band_color(axis: str) -> tuple[int, int, int]:
    return tuple(int(_BAND * c + (1 - _BAND) * 128) for c in AXIS_COLORS[axis])


def default_blueprint(extra: rrb.Container | None = None, follow: dict[str, tuple[float, float]] | None = None,
                      plan: bool = False) -> rrb.Blueprint:
    """The trial layout: the bias first and largest (per axis the whole history beside the view that follows the
    converged estimate, its range ``follow[axis]`` µg, autoscaled without), its 1σ with the limit under it (its
    range ``follow["sigma"]``) and beside it the temperatures (the IMU's, the chamber's) |
    the verdict, the 3D table, and the rest in tabs (stream health in one compact grid, observability,
    alignment, drift), with ``plan`` the plan's document under the verdict [| ``extra``, a further column: a trial
    kind's own views]."""
    follow = follow or {}
    rows = [rrb.Horizontal(
        rrb.TimeSeriesView(origin=f"/bias/{a}", name=f"bias {a} (µg), whole trial",
                           plot_legend=rrb.PlotLegend(visible=a == "x")),
        rrb.TimeSeriesView(origin=f"/bias/{a}", name=f"bias {a} (µg), converged: ±{FOLLOW_SIGMAS:g}σ about the estimate",
                           axis_y=rrb.ScalarAxis(range=follow[a]) if a in follow else None,
                           plot_legend=rrb.PlotLegend(visible=False)),
        column_shares=[1, 1]) for a in AXES]  # fmt: skip
    sigma = rrb.TimeSeriesView(origin="/sigma", name="bias 1σ (µg), limit, convergence deadline",
                               axis_y=rrb.ScalarAxis(range=follow["sigma"]) if "sigma" in follow else None)
    temperature = rrb.TimeSeriesView(origin="/", contents=[f"/{path}" for path in TEMPERATURES],
                                     name="temperature (°C): IMU, chamber, set point")
    tabs = rrb.Tabs(
        rrb.Grid(*(rrb.TimeSeriesView(origin=f"/health/{metric}", name=title) for metric, title in HEALTH_VIEWS),
                 grid_columns=3, name="stream health"),
        rrb.Vertical(
            rrb.TimeSeriesView(origin="/observability/rank", name="scaled Gram rank",
                               axis_y=rrb.ScalarAxis(range=(0.0, 13.0))),
            rrb.TimeSeriesView(origin="/observability/log10_condition", name="log10 condition number",
                               plot_legend=rrb.PlotLegend(visible=False)),
            name="observability"),
        rrb.Vertical(*(rrb.TimeSeriesView(origin=f"/alignment/{angle}", name=f"{angle} error (deg)",
                                          plot_legend=rrb.PlotLegend(visible=angle == "pitch")) for angle in ANGLES),
                     name="alignment"),
        rrb.Vertical(*(rrb.TimeSeriesView(origin=f"/drift/{a}", name=f"bias drift {a} (µg/h)",
                                          plot_legend=rrb.PlotLegend(visible=False)) for a in AXES),
                     name="bias drift"),
    )  # fmt: skip
    plan_view = [rrb.TextDocumentView(origin="/plan", name="plan: steps, verdicts, time left")] if plan else []
    side = rrb.Vertical(
        rrb.TextDocumentView(origin="/verdict", name="verdict"),
        *plan_view,
        rrb.Spatial3DView(origin="/world", name="turntable and apparent gravity in i_b0"),
        tabs,
        row_shares=[3] + [2] * len(plan_view) + [3, 2],
        name="verdict, table, health",
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(*rows, rrb.Horizontal(sigma, temperature, column_shares=[2, 1]), row_shares=[3, 3, 3, 2],
                         name="accelerometer bias"),
            side,
            *([extra] if extra is not None else []),
            column_shares=[3, 2] + ([2] if extra is not None else []),
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
    )


def log_series_styles(rec: rr.RecordingStream, with_truth: bool) -> None:
    """The names, colours and widths of every time series but the bias's (static; :mod:`hil.viewer.bias_view`)."""
    for a in AXES:
        names, colors, widths = ["estimate", "−3σ", "+3σ"], [AXIS_COLORS[a], band_color(a), band_color(a)], [2, 1, 1]
        if with_truth:
            names, colors, widths = names + ["truth"], colors + [TRUTH_COLOR], widths + [1.5]
        rec.log(f"drift/{a}", rr.SeriesLines(names=names, colors=colors, widths=widths), static=True)
    rec.log("sigma", rr.SeriesLines(names=list(AXES), colors=[AXIS_COLORS[a] for a in AXES]), static=True)
    rec.log("sigma/limit", rr.SeriesLines(names="limit", colors=LIMIT_COLOR, widths=1.5), static=True)
    rec.log("sigma/converged_by", rr.SeriesLines(names="converged by (limit)", colors=LIMIT_COLOR, widths=1.5),
            static=True)
    rec.log("observability/rank", rr.SeriesLines(names=["12-state (with bias)", "9-state (method 1)"],
                                                 colors=[(55, 126, 184), (230, 85, 13)]), static=True)  # fmt: skip
    rec.log("observability/log10_condition", rr.SeriesLines(names="log10 cond", colors=(55, 126, 184)), static=True)
    for angle in ANGLES:
        methods = ("method1", "method2") if angle == "yaw" else ("method1", "method2", "theoretical")
        rec.log(f"alignment/{angle}", rr.SeriesLines(names=[_METHOD_NAMES[m] for m in methods],
                                                     colors=[_METHOD_COLORS[m] for m in methods]), static=True)  # fmt: skip
    rec.log("table/angles_deg", rr.SeriesLines(names=["outer", "middle", "inner"],
                                               colors=[(55, 126, 184), (77, 175, 74), (228, 26, 28)]), static=True)  # fmt: skip
