"""The noise characterisation's files: ``noise.json`` (docs/contracts.md, "noise.json") and ``allan.png``.

Terms and deviations in datasheet units (``hil.estimation.allan.GYRO_UNITS``, ``ACCEL_UNITS``); a term
the record cannot resolve is null. matplotlib is imported when the figure is drawn, not with this module.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from hil.estimation.allan import (
    ACCEL_UNITS,
    FLICKER_FLOOR,
    GYRO_UNITS,
    AllanAnalysis,
    Term,
    TermUnits,
)
from hil.outputs.figures import pyplot

NOISE_JSON, ALLAN_PNG = "noise.json", "allan.png"
# (sensor, its units, the noise.json key of each term in the order white, bias instability, random walk)
SENSORS = (
    ("gyro", GYRO_UNITS, ("arw_deg_per_sqrt_h", "bias_instability_dph", "rrw_deg_per_h_per_sqrt_h")),
    ("accel", ACCEL_UNITS, ("vrw_m_per_s_per_sqrt_h", "bias_instability_ug", "rrw_m_per_s2_per_sqrt_h")),
)
ADEV_UNITS = {"gyro": "deg/h", "accel": "ug"}
TERMS = ("white", "bias_instability", "random_walk")
# IEEE 952 read-off points: the -1/2 line at tau = 1 s is N, the +1/2 line at tau = 3 s is K.
WHITE_READ_TAU_S, WALK_READ_TAU_S = 1.0, 3.0


def _terms(analysis: AllanAnalysis, units: TermUnits) -> list[tuple[Term, ...]]:
    """Per term (white, bias instability, random walk) the per-axis Terms in datasheet units."""
    return [tuple(t.scaled(getattr(units, name)) for t in getattr(analysis, name)) for name in TERMS]


def _rows(values: np.ndarray) -> list[list[float]]:
    """(M, 3) -> three per-axis lists."""
    return [[float(v) for v in column] for column in np.asarray(values).T]


def noise_document(gyro: AllanAnalysis, accel: AllanAnalysis) -> dict:
    """The noise.json document (docs/contracts.md, "noise.json") from the gyro and accelerometer analyses (same tau)."""
    if not np.array_equal(gyro.tau, accel.tau):
        raise ValueError("gyro and accelerometer records differ in length or rate: analyse them over the same samples")
    doc: dict = {}
    ci: dict = {"level": gyro.level, "adev": {}}
    for (sensor, units, keys), analysis in zip(SENSORS, (gyro, accel)):
        terms = _terms(analysis, units)
        doc[sensor] = {key: [t.value for t in per_axis] for key, per_axis in zip(keys, terms)}
        ci[sensor] = {key: {"lower": [t.lower for t in per_axis], "upper": [t.upper for t in per_axis]}
                      for key, per_axis in zip(keys, terms)}
        ci["adev"][sensor] = {"lower": _rows(analysis.lower / units.adev), "upper": _rows(analysis.upper / units.adev)}
    doc["tau_s"] = [float(t) for t in gyro.tau]
    doc["adev"] = {s: _rows(a.adev / u.adev) for (s, u, _), a in zip(SENSORS, (gyro, accel))}
    doc["adev_units"] = ADEV_UNITS
    doc["edf"] = {s: _rows(a.edf) for (s, _, _), a in zip(SENSORS, (gyro, accel))}
    doc["noise_alpha"] = {s: [[int(v) for v in column] for column in a.alpha.T]
                          for (s, _, _), a in zip(SENSORS, (gyro, accel))}
    doc["ci"] = ci
    doc["duration_s"] = gyro.duration_s
    return doc


def write_noise(out: Path, doc: dict, gyro: AllanAnalysis, accel: AllanAnalysis, figure: bool = True) -> dict:
    """Writes the noise.json document ``doc`` as OUT/noise.json and, unless figure is False, OUT/allan.png of
    the analyses it came from; returns the document."""
    out.mkdir(parents=True, exist_ok=True)
    (out / NOISE_JSON).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    if figure:
        plot_allan(out / ALLAN_PNG, gyro, accel)
    return doc


def noise_summary(doc: dict, out: Path) -> str:
    """The console summary of a noise.json document: every term per axis in datasheet units."""
    gaps = f", {doc['missing']} missing in gaps" if doc.get("missing") else ""
    lines = [f"noise of {doc['samples']} samples ({doc['duration_s']:.0f} s{gaps}): outputs in {out}"]
    for sensor, _, keys in SENSORS:
        for key in keys:
            values = doc[sensor][key]
            lines.append(f"  {sensor} {key}: " + ", ".join("not resolved" if v is None else f"{v:.4g}" for v in values))
    return "\n".join(lines)


def plot_allan(path: Path, gyro: AllanAnalysis, accel: AllanAnalysis) -> None:
    """Log-log Allan deviation, one panel per sensor kind: the three axes with their intervals, each
    fitted term as its slope line (-1/2, 0, +1/2) and the points the terms are read at."""
    plt = pyplot()
    from hil.outputs.log_labels import use_plain_log_labels  # with matplotlib, which pyplot() has imported

    fig, panels = plt.subplots(1, 2, figsize=(12, 5))
    for ax, (sensor, units, _), analysis in zip(panels, SENSORS, (gyro, accel)):
        tau = analysis.tau
        white, flicker, walk = _terms(analysis, units)
        for k, axis in enumerate("xyz"):
            colour = f"C{k}"
            adev = analysis.adev[:, k] / units.adev
            yerr = np.vstack([adev - analysis.lower[:, k] / units.adev, analysis.upper[:, k] / units.adev - adev])
            ax.errorbar(tau, adev, yerr=yerr, fmt="o-", ms=3, color=colour, capsize=2, label=f"{axis}")
            ax.plot(tau, analysis.model_adev[:, k] / units.adev, color=colour, alpha=0.5, lw=3)
            floor_tau = tau[np.argmin(analysis.model_adev[:, k])]
            _slope_lines(ax, tau, colour, (white[k], flicker[k], walk[k]), floor_tau, units)
        ax.set_xscale("log")
        ax.set_yscale("log")
        use_plain_log_labels(ax.xaxis)
        use_plain_log_labels(ax.yaxis)
        ax.set_xlabel("tau (s)")
        ax.set_ylabel(f"Allan deviation ({ADEV_UNITS[sensor]})")
        ax.set_title(f"{sensor}: slopes -1/2 (:), 0 (--), +1/2 (-.); read-off points marked")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(title=f"axis ({analysis.level:.1%} intervals)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _slope_lines(
    ax, tau: np.ndarray, colour: str, terms: tuple[Term, Term, Term], floor_tau: float, units: TermUnits
) -> None:
    """One axis's fitted terms as lines in deviation units, and the IEEE 952 read-off points: N on the
    -1/2 line at 1 s, 0.664 B at the model's minimum (floor_tau), K on the +1/2 line at 3 s."""
    white, flicker, walk = terms
    if white.value is not None:
        n = white.value * units.white / units.adev
        ax.plot(tau, n / np.sqrt(tau), ":", color=colour)
        ax.plot(WHITE_READ_TAU_S, n, "s", color=colour, mfc="none", ms=8)
    if flicker.value is not None:
        floor = math.sqrt(FLICKER_FLOOR) * flicker.value * units.bias_instability / units.adev
        ax.plot(tau, np.full_like(tau, floor), "--", color=colour)
        ax.plot(floor_tau, floor, "D", color=colour, mfc="none", ms=8)
    if walk.value is not None:
        k = walk.value * units.random_walk / units.adev
        ax.plot(tau, k * np.sqrt(tau / 3.0), "-.", color=colour)
        ax.plot(WALK_READ_TAU_S, k, "^", color=colour, mfc="none", ms=8)
