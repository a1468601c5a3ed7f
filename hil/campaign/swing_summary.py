"""``OUT/summary.json``: the estimator's consistency per sweep point, over the runs of that point.

With e the bias error (estimate minus truth) of M runs and sigma their reported 1-sigma, per axis:
the ratio ``r = std(e) / mean(sigma)`` (std with M - 1 degrees of freedom). For a consistent estimator
(e ~ N(0, sigma^2), sigma nearly the same in every run) ``(M - 1) r^2 ~ chi2(M - 1)``, so r lies in
``[sqrt(chi2_0.025(M-1) / (M-1)), sqrt(chi2_0.975(M-1) / (M-1))]`` with 95 % probability. The normalised
estimation error squared of a run, ``NEES = sum_axes (e / sigma)^2`` (3 degrees of freedom), has a mean
over M runs with ``M * mean ~ chi2(3 M)``: the band ``[chi2_0.025(3M) / M, chi2_0.975(3M) / M]``
(Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 5.4.2).
result.json reports per-axis sigmas only, so the NEES here ignores their cross-correlation.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from hil.campaign.entries import Entry, entry_label, row_entry, with_unit
from hil.campaign.runs import ERROR, row_order
from hil.outputs.result import strict_json

SUMMARY_NAME = "summary.json"
LEVEL = 0.95  # of the bands
QUANTILES = (0.05, 0.5, 0.95)  # of the convergence time
AXES = 3
ESTIMATE, SIGMA, TRUTH = "estimate.accel_bias_ug", "estimate.accel_bias_sigma_ug", "truth.accel_bias_ug"


def ratio_band(runs: int, level: float = LEVEL) -> tuple[float, float]:
    """Where std(e)/mean(sigma) of ``runs`` runs of a consistent estimator lies with probability ``level``."""
    dof = runs - 1
    tail = (1.0 - level) / 2.0
    return (float(np.sqrt(stats.chi2.ppf(tail, dof) / dof)), float(np.sqrt(stats.chi2.ppf(1.0 - tail, dof) / dof)))


def nees_band(runs: int, dof: int = AXES, level: float = LEVEL) -> tuple[float, float]:
    """Where the mean NEES (``dof`` degrees of freedom) of ``runs`` runs lies with probability ``level``."""
    tail = (1.0 - level) / 2.0
    return (float(stats.chi2.ppf(tail, dof * runs) / runs), float(stats.chi2.ppf(1.0 - tail, dof * runs) / runs))


def _vector(row: dict[str, Any], key: str) -> list[float | None]:
    return [row.get(f"{key}.{i}") for i in range(AXES)]


def bias_error(row: dict[str, Any]) -> np.ndarray | None:
    """Estimate minus truth (µg) of a run; the truth at the trial's end when the drift model estimates it
    there (docs/contracts.md, "result.json"). None when the run has no estimate or no truth."""
    estimate, truth = _vector(row, ESTIMATE), _vector(row, TRUTH)
    if row.get(ERROR) is not None or None in estimate or None in truth or None in _vector(row, SIGMA):
        return None
    truth = np.array(truth, dtype=float)
    if row.get("estimate.bias_model") == "drift":
        drift = np.array([row.get(f"truth.accel_drift_ug_per_h.{i}") or 0.0 for i in range(AXES)])
        truth = truth + drift * row["trial.duration_s"] / 3600.0
    return np.array(estimate, dtype=float) - truth


def consistency(errors: np.ndarray, sigmas: np.ndarray) -> dict[str, Any]:
    """The statistics of M runs' errors (M, 3) against their reported sigmas (M, 3), both in µg."""
    m = len(errors)
    out: dict[str, Any] = {"with_estimate": m, "error_mean_ug": errors.mean(axis=0).tolist(),
                           "sigma_mean_ug": sigmas.mean(axis=0).tolist()}
    if m < 2:
        return out
    std = errors.std(axis=0, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero sigma (error-free runs): no ratio, no NEES
        ratio = std / sigmas.mean(axis=0)
        nees = float(np.mean(np.sum((errors / sigmas) ** 2, axis=1)))
    low, high = ratio_band(m)
    nees_low, nees_high = nees_band(m)
    return {**out, "error_std_ug": std.tolist(), "ratio": ratio.tolist(), "ratio_band": [low, high],
            "ratio_inside": [bool(low <= r <= high) for r in ratio],
            "nees_mean": nees, "nees_band": [nees_low, nees_high], "nees_inside": bool(nees_low <= nees <= nees_high)}


def point_summary(point: int, values: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The summary of one sweep point's rows."""
    done = [(e, row) for row in rows if (e := bias_error(row)) is not None]
    out: dict[str, Any] = {"point": point, "values": values, "runs": len(rows),
                           "failed": sum(row.get(ERROR) is not None for row in rows), "with_estimate": len(done)}
    if done:
        errors = np.array([e for e, _ in done])
        sigmas = np.array([_vector(row, SIGMA) for _, row in done], dtype=float)
        out.update(consistency(errors, sigmas))
    converged = [row["estimate.converged_at_s"] for _, row in done if row.get("estimate.converged_at_s") is not None]
    out["converged_at_s"] = {f"q{round(q * 100):02d}": float(np.quantile(converged, q)) if converged else None
                             for q in QUANTILES}
    out["not_converged"] = len(done) - len(converged)
    return out


def summarise(points: list[dict[str, Any]], rows: list[dict[str, Any]], cluster: dict[str, Any],
              point: Callable[[int, dict[str, Any], list[dict[str, Any]]], dict[str, Any]] = point_summary,
              entries: list[Entry] | None = None) -> dict[str, Any]:
    """summary.json: the statistics (``point``: of the campaign's kind) of every entry (:mod:`hil.campaign.entries`;
    by default each sweep point, as a one-unit campaign's), the campaign's counts and the cluster it ran on."""
    by_entry: dict[Entry, list[dict[str, Any]]] = {e: [] for e in entries or [(p, None) for p in range(len(points))]}
    for row in sorted(rows, key=row_order):  # the same sums, bit for bit, whatever order the runs completed in
        by_entry[row_entry(row)].append(row)
    return {"runs": len(rows), "failed": sum(row.get(ERROR) is not None for row in rows), "level": LEVEL,
            "points": [with_unit(point(p, points[p], found), unit) for (p, unit), found in by_entry.items()],
            "cluster": cluster}


def write_summary(out: Path, summary: dict[str, Any]) -> Path:
    path = out / SUMMARY_NAME
    path.write_text(json.dumps(strict_json(summary), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return path


def point_lines(p: dict[str, Any]) -> list[str]:
    """The console line of a point: the consistency ratio per axis and the mean NEES."""
    values = entry_label(p)
    if "ratio" not in p:
        return [f"  {values}: {p['with_estimate']} runs with an estimate: too few for statistics"]
    ratio = " ".join(f"{r:.3f}" for r in p["ratio"])
    return [(f"  {values}: std(error)/sigma {ratio} (band {p['ratio_band'][0]:.3f}-{p['ratio_band'][1]:.3f}), NEES "
             f"{p['nees_mean']:.3f} (band {p['nees_band'][0]:.3f}-{p['nees_band'][1]:.3f})")]
