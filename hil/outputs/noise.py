"""The noise characterisation's files: ``noise.json`` (docs/contracts.md, "noise.json") and ``allan.png``.

Terms and deviations in datasheet units (``hil.estimation.allan.GYRO_UNITS``, ``ACCEL_UNITS``); a term
the record cannot resolve is null, with its reason under ``unresolved``. matplotlib is imported when the
figure is drawn, not with this module.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from hil.estimation.allan import ACCEL_UNITS, GYRO_UNITS, AllanAnalysis, TermUnits
from hil.estimation.allan_fit import FLICKER_FLOOR, TERM_NAMES, Term
from hil.outputs.figures import pyplot
from hil.outputs.output_dir import NOISE_JSON

ALLAN_PNG = "allan.png"
# (sensor, its units, the noise.json key of each term in the order of TERM_NAMES: quantisation, white, bias
# instability, random walk, ramp)
SENSORS = (
    ("gyro", GYRO_UNITS, ("quantization_urad", "arw_deg_per_sqrt_h", "bias_instability_dph",
                          "rrw_deg_per_h_per_sqrt_h", "ramp_dph_per_h")),
    ("accel", ACCEL_UNITS, ("quantization_m_per_s", "vrw_m_per_s_per_sqrt_h", "bias_instability_ug",
                            "rrw_m_per_s2_per_sqrt_h", "ramp_ug_per_h")),
)
ADEV_UNITS = {"gyro": "deg/h", "accel": "ug"}
# IEEE 952 read-off taus (s): the -1 line at sqrt(3) is Q, the -1/2 line at 1 N, the +1/2 line at 3 K, the +1
# line at sqrt(2) R
READ_TAU_S = {"quantization": math.sqrt(3.0), "white": 1.0, "random_walk": 3.0, "ramp": math.sqrt(2.0)}
# each term's deviation per unit coefficient at tau, and its line's style
_SHAPES = {"quantization": (lambda tau: math.sqrt(3.0) / tau, (0, (6, 2, 1, 2, 1, 2))),
           "white": (lambda tau: 1.0 / np.sqrt(tau), ":"),
           "bias_instability": (lambda tau: np.full_like(tau, math.sqrt(FLICKER_FLOOR)), "--"),
           "random_walk": (lambda tau: np.sqrt(tau / 3.0), "-."),
           "ramp": (lambda tau: tau / math.sqrt(2.0), (0, (10, 3)))}
_MARKERS = {"quantization": "o", "white": "s", "bias_instability": "D", "random_walk": "^", "ramp": "v"}


def _terms(analysis: AllanAnalysis, units: TermUnits) -> list[tuple[Term, ...]]:
    """Per term (in the order of TERM_NAMES) the per-axis Terms in datasheet units."""
    return [tuple(t.scaled(getattr(units, name)) for t in getattr(analysis, name)) for name in TERM_NAMES]


def _rows(values: np.ndarray) -> list[list[float]]:
    """(M, 3) -> three per-axis lists."""
    return [[float(v) for v in column] for column in np.asarray(values).T]


def noise_document(gyro: AllanAnalysis, accel: AllanAnalysis) -> dict:
    """The noise.json document (docs/contracts.md, "noise.json") from the gyro and accelerometer analyses (same tau)."""
    if not np.array_equal(gyro.tau, accel.tau):
        raise ValueError("gyro and accelerometer records differ in length or rate: analyse them over the same samples")
    doc: dict = {}
    ci: dict = {"level": gyro.level, "adev": {}}
    unresolved: dict = {}
    for (sensor, units, keys), analysis in zip(SENSORS, (gyro, accel)):
        terms = _terms(analysis, units)
        doc[sensor] = {key: [t.value for t in per_axis] for key, per_axis in zip(keys, terms)}
        unresolved.update({f"{sensor}.{key}.{k}": t.reason for key, per_axis in zip(keys, terms)
                           for k, t in enumerate(per_axis) if t.value is None})
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
    doc["unresolved"] = unresolved
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
    resolved term as its slope line (-1, -1/2, 0, +1/2, +1) and the points the terms are read at."""
    plt = pyplot()
    from hil.outputs.log_labels import use_plain_log_labels  # with matplotlib, which pyplot() has imported

    fig, panels = plt.subplots(1, 2, figsize=(12, 5))
    for ax, (sensor, units, _), analysis in zip(panels, SENSORS, (gyro, accel)):
        tau = analysis.tau
        terms = _terms(analysis, units)
        for k, axis in enumerate("xyz"):
            colour = f"C{k}"
            adev = analysis.adev[:, k] / units.adev
            yerr = np.vstack([adev - analysis.lower[:, k] / units.adev, analysis.upper[:, k] / units.adev - adev])
            ax.errorbar(tau, adev, yerr=yerr, fmt="o-", ms=3, color=colour, capsize=2, label=f"{axis}")
            ax.plot(tau, analysis.model_adev[:, k] / units.adev, color=colour, alpha=0.5, lw=3)
            floor_tau = tau[np.argmin(analysis.model_adev[:, k])]
            _slope_lines(ax, tau, colour, [per_axis[k] for per_axis in terms], floor_tau, units)
        ax.set_xscale("log")
        ax.set_yscale("log")
        use_plain_log_labels(ax.xaxis)
        use_plain_log_labels(ax.yaxis)
        ax.set_xlabel("tau (s)")
        ax.set_ylabel(f"Allan deviation ({ADEV_UNITS[sensor]})")
        ax.set_title(f"{sensor}: Q -1 (-..), N -1/2 (:), B 0 (--), K +1/2 (-.), R +1 (long dashes); "
                     "read-off points marked", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(title=f"axis ({analysis.level:.1%} intervals)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _slope_lines(ax, tau: np.ndarray, colour: str, terms: list[Term], floor_tau: float, units: TermUnits) -> None:
    """One axis's resolved terms (in the order of TERM_NAMES) as lines in deviation units, and the IEEE 952
    read-off points: Q on the -1 line at sqrt(3) s, N on the -1/2 line at 1 s, 0.664 B at the model's minimum
    (floor_tau), K on the +1/2 line at 3 s, R on the +1 line at sqrt(2) s."""
    for name, fitted in zip(TERM_NAMES, terms):
        if fitted.value is None:
            continue
        shape, style = _SHAPES[name]
        coefficient = fitted.value * getattr(units, name) / units.adev
        ax.plot(tau, coefficient * shape(tau), linestyle=style, color=colour)
        at = np.array([READ_TAU_S.get(name, floor_tau)])
        ax.plot(at, coefficient * shape(at), _MARKERS[name], color=colour, mfc="none", ms=8)
