"""The view of a noise characterisation (``hil noise --viewer``, ``--rerun``): each sensor's Allan deviation per
axis, log-log, as it forms over the record, and the noise terms so far.

Rerun's plots run along a timeline and have no logarithmic axis, so the curves are 2-D line strips in a plane of
decades: x = log10 tau (s), y = -log10 ADEV (up the screen, whose y points down), with a line and a label at
every decade the curves span (``/allan/<sensor>/grid``). Each is logged at the record time it describes, on
``trial_time``: the analysis of the record's first ``T / 2^k`` seconds, then the whole record's. The time panel
steps back through them; the view shows the latest. Entity paths in docs/viewer.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hil.outputs.measurements import format_value
from hil.outputs.noise import SENSORS
from hil.viewer.blueprint import AXES, AXIS_COLORS, TIMELINE, band_color
from hil.viewer.own_recording import OwnRecording

NOISE_RRD = "noise.rrd"
GRID_COLOR = (170, 170, 170)
LABEL_GAP = 0.25  # decades between a grid line and its label
TERMS = "allan/terms"
COLORS_NAMED = "x red, y green, z blue, each with its interval"  # hil.viewer.blueprint.AXIS_COLORS


def noise_blueprint(units: dict[str, str]) -> rrb.Blueprint:
    """The noise layout: per sensor its log-log plane (``units``: sensor -> ADEV unit), then the terms so far."""
    views = [rrb.Spatial2DView(origin=f"/allan/{sensor}", name=f"{sensor} Allan deviation ({unit}) vs tau (s), "
                                                               f"log-log, as it forms: {COLORS_NAMED}")
             for sensor, unit in units.items()]  # fmt: skip
    return rrb.Blueprint(
        rrb.Vertical(*views, rrb.TextDocumentView(origin=f"/{TERMS}", name="noise terms so far"),
                     row_shares=[3] * len(views) + [2], name="noise"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
    )


def curve_points(tau_s: np.ndarray, adev: np.ndarray) -> np.ndarray:
    """(N, 2) points of a curve in the plane of decades: (log10 tau, -log10 ADEV); taus without a value left out."""
    tau, value = np.asarray(tau_s, dtype=float), np.asarray(adev, dtype=float)
    kept = np.isfinite(value) & (value > 0)
    return np.column_stack((np.log10(tau[kept]), -np.log10(value[kept])))


def decade_grid(points: np.ndarray, unit: str) -> tuple[list[np.ndarray], np.ndarray, list[str]]:
    """The lines at every decade the ``points`` span (rounded out), and their labels' positions and texts: tau
    under the bottom line, the deviation left of the left one."""
    x0, x1 = np.floor(points[:, 0].min()), np.ceil(points[:, 0].max())
    y0, y1 = np.floor(points[:, 1].min()), np.ceil(points[:, 1].max())
    lines = [np.array([[x, y0], [x, y1]]) for x in np.arange(x0, x1 + 1)]
    lines += [np.array([[x0, y], [x1, y]]) for y in np.arange(y0, y1 + 1)]
    labels = [(np.array([x, y1 + LABEL_GAP]), f"{10.0 ** x:g} s") for x in np.arange(x0, x1 + 1)]
    labels += [(np.array([x0 - 2 * LABEL_GAP, y]), f"{10.0 ** -y:g} {unit}") for y in np.arange(y0, y1 + 1)]
    return lines, np.array([p for p, _ in labels]), [text for _, text in labels]


def terms_markdown(doc: dict, recorded_s: float, total_s: float) -> str:
    """The noise terms of ``doc`` (a noise.json document, :func:`hil.outputs.noise.noise_document`) as markdown:
    a row per term, its value per axis as report.html shows it (— where the record cannot resolve it)."""
    lines = [f"## Noise terms of the first {recorded_s:.4g} s of {total_s:.4g} s", "",
             "| term | x | y | z |", "|---|---|---|---|"]  # fmt: skip
    for sensor, _, keys in SENSORS:
        for key in keys:
            values = ["—" if v is None else format_value(v) for v in doc[sensor][key]]
            lines.append(f"| {sensor} `{key}` | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


class AllanView(OwnRecording):
    """The noise view in ``mode`` (``spawn``, ``serve`` or ``save``), written to OUT/noise.rrd in every mode
    (:class:`~hil.viewer.own_recording.OwnRecording`); :meth:`show` logs one analysis."""

    def __init__(self, mode: str, out: Path, units: dict[str, str], bind: str = "127.0.0.1") -> None:
        super().__init__(mode, Path(out) / NOISE_RRD, noise_blueprint(units), "noise characterisation", bind)
        self.units = dict(units)

    def show(self, recorded_s: float, total_s: float, doc: dict) -> None:
        """The analysis ``doc`` (a noise.json document) of the record's first ``recorded_s`` of ``total_s`` s,
        at that record time: per sensor and axis the curve with its confidence interval, the decade grid, and
        the terms."""
        rec = self.rec
        rec.set_time(TIMELINE, duration=recorded_s)
        tau = np.asarray(doc["tau_s"])
        for sensor, unit in self.units.items():
            every = []
            for k, axis in enumerate(AXES):
                strips = [curve_points(tau, doc["adev"][sensor][k]),
                          curve_points(tau, doc["ci"]["adev"][sensor]["lower"][k]),
                          curve_points(tau, doc["ci"]["adev"][sensor]["upper"][k])]
                rec.log(f"allan/{sensor}/{axis}", rr.LineStrips2D(
                    strips, colors=[AXIS_COLORS[axis], band_color(axis), band_color(axis)], radii=[0.012, 0.005, 0.005],
                    draw_order=2.0))  # fmt: skip
                every.append(strips[0])
            lines, at, texts = decade_grid(np.vstack(every), unit)
            rec.log(f"allan/{sensor}/grid", rr.LineStrips2D(lines, colors=GRID_COLOR, radii=0.003, draw_order=0.0))
            rec.log(f"allan/{sensor}/grid/labels", rr.Points2D(at, labels=texts, colors=GRID_COLOR, radii=0.01,
                                                               show_labels=True))  # fmt: skip
        rec.log(TERMS, rr.TextDocument(terms_markdown(doc, recorded_s, total_s), media_type=rr.MediaType.MARKDOWN))
