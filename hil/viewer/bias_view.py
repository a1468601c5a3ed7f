"""The bias of a trial's view: per axis the estimate, its 3-sigma band, the table-referenced bias and (emulated)
the truth as separate entities ``/bias/<axis>/<series>``, and the range of the view that follows the converged
estimate (a few sigma about the latest estimate, sent as the blueprint's scalar axis range)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr

from hil.estimation.online import Snapshot
from hil.units import UG
from hil.viewer.blueprint import AXES, AXIS_COLORS, FOLLOW_SIGMAS, TRUTH_COLOR, band_color

# series: name shown, width; the colour is the axis's (the band's mixed with grey), the reference's black
SERIES = {"estimate": ("estimate", 2.0), "sigma3_upper": ("+3σ", 1.0), "sigma3_lower": ("−3σ", 1.0),
          "table_reference": ("table-referenced", 1.5), "truth": ("truth", 1.5)}  # fmt: skip
REFERENCE_COLOR = (40, 40, 40)
FOLLOW_FLOOR_UG = 0.5  # the followed view spans at least the latest estimate ± this
REFERENCE_SIGMAS = 20.0  # a reference (table, truth) this close to the estimate is kept in the followed view
RESEND_CHANGE = 0.25  # the followed ranges are sent again once a bound moves by this fraction of their width


@dataclass(frozen=True)
class BiasTruth:
    """An emulated trial's accelerometer bias, the reference its view draws: ``bias`` (3,) m/s^2 at the start and
    its ``drift`` (3,) m/s^3 (None: constant)."""

    bias: np.ndarray
    drift: np.ndarray | None = None


def series_color(axis: str, series: str) -> tuple[int, int, int]:
    if series == "estimate":
        return AXIS_COLORS[axis]
    if series.startswith("sigma3"):
        return band_color(axis)
    return TRUTH_COLOR if series == "truth" else REFERENCE_COLOR


def log_bias_styles(rec, with_truth: bool, prefix: str = "", series: tuple[str, ...] = tuple(SERIES)) -> None:
    """The static name, colour and width of every bias series (of ``series``), at ``<prefix>bias/<axis>/<series>``."""
    for a in AXES:
        for kind in series:
            name, width = SERIES[kind]
            if kind != "truth" or with_truth:
                rec.log(f"{prefix}bias/{a}/{kind}",
                        rr.SeriesLines(names=name, colors=series_color(a, kind), widths=width), static=True)


def bias_rows(snaps: list[Snapshot], truth: BiasTruth | None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The rows (t, values µg) of each bias entity for these snapshots; rows without a value left out. The truth
    at t is ``truth.bias + truth.drift t`` (the bias at t, as the estimate is)."""
    t = np.fromiter((s.t for s in snaps), float, len(snaps))
    nan3 = np.full(3, np.nan)
    bias = np.array([s.full.bias if s.full.bias is not None else nan3 for s in snaps]).reshape(-1, 3) / UG
    sigma = np.array([s.full.bias_sigma if s.full.bias_sigma is not None else nan3 for s in snaps]).reshape(-1, 3) / UG
    table = np.array([s.table_bias if s.table_bias is not None else nan3 for s in snaps]).reshape(-1, 3) / UG
    columns = {"estimate": bias, "sigma3_upper": bias + 3.0 * sigma, "sigma3_lower": bias - 3.0 * sigma,
               "table_reference": table}  # fmt: skip
    if truth is not None:
        start = np.asarray(truth.bias, dtype=float)
        drift = np.zeros(3) if truth.drift is None else np.asarray(truth.drift, dtype=float)
        columns["truth"] = np.where(np.isnan(bias), np.nan, (start + np.outer(t, drift)) / UG)
    rows = {}
    for k, a in enumerate(AXES):
        for series, values in columns.items():
            kept = ~np.isnan(values[:, k])
            if kept.any():
                rows[f"bias/{a}/{series}"] = (t[kept], values[kept, k])
    return rows


def follow_ranges(snap: Snapshot, truth_bias: np.ndarray | None = None) -> dict[str, tuple[float, float]] | None:
    """Per axis the followed view's range (µg): the estimate ± ``FOLLOW_SIGMAS`` sigma (at least
    ``FOLLOW_FLOOR_UG``), widened to the table-referenced bias and the truth where they lie within
    ``REFERENCE_SIGMAS`` sigma of it; None while the bias is not estimated."""
    if snap.full.bias is None or snap.full.bias_sigma is None:
        return None
    ranges = {}
    for k, a in enumerate(AXES):
        estimate, sigma = snap.full.bias[k] / UG, snap.full.bias_sigma[k] / UG
        half = max(FOLLOW_SIGMAS * sigma, FOLLOW_FLOOR_UG)
        lo, hi = estimate - half, estimate + half
        for reference in (snap.table_bias, truth_bias):
            if reference is not None and abs(reference[k] / UG - estimate) <= REFERENCE_SIGMAS * sigma:
                lo, hi = min(lo, reference[k] / UG - 0.2 * half), max(hi, reference[k] / UG + 0.2 * half)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            return None
        ranges[a] = (float(lo), float(hi))
    return ranges


def moved(old: dict[str, tuple[float, float]] | None, new: dict[str, tuple[float, float]]) -> bool:
    """Whether some bound of ``new`` lies ``RESEND_CHANGE`` of its width away from ``old``'s (or there is none)."""
    if old is None:
        return True
    return any(max(abs(new[a][0] - old[a][0]), abs(new[a][1] - old[a][1])) > RESEND_CHANGE * (new[a][1] - new[a][0])
               for a in new)
