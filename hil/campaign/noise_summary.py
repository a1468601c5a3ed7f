"""summary.json of a noise campaign: per sweep point, noise term and axis, how the fitted terms of its runs
compare with the terms the config puts in, and how often the reported interval holds them.

With M runs whose term is resolved, v_i their fitted values and t the truth: the mean and std (M - 1
degrees of freedom) of v and the mean relative error mean((v_i - t) / t); with M' runs that give the term
an interval (a term the fit holds but cannot resolve has its interval, the upper limit a lab quotes, and
no value), the coverage c = K / M', K the runs whose interval [lower_i, upper_i] contains t. When the
intervals have their nominal level p (noise.json ``ci.level``), K ~ Binomial(M', p), so c lies in
``[F^-1(0.025) / M', F^-1(0.975) / M']`` (F the binomial distribution function) with at least 95 %
probability: a coverage outside that band says the intervals are too narrow (below) or too wide (above);
the point's headline ``coverage_consistent`` is every coverage inside its band (``coverage_above`` and
``coverage_below`` count the others). A run that cannot resolve a term counts in ``unresolved``. A term the
config does not put in (truth 0) is counted when a run resolves it (``resolved``), with no statistics.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

from hil.campaign.entries import entry_label
from hil.campaign.runs import ERROR, TRUTH
from hil.campaign.swing_summary import LEVEL
from hil.outputs.noise import SENSORS

AXES = 3
TERM_KEYS = tuple(f"{sensor}.{key}" for sensor, _, keys in SENSORS for key in keys)  # gyro.arw_deg_per_sqrt_h, ...
CI_LEVEL = "ci.level"


def coverage_band(runs: int, nominal: float, level: float = LEVEL) -> tuple[float, float]:
    """Where the coverage of ``runs`` intervals of nominal level ``nominal`` lies with probability >= ``level``."""
    tail = (1.0 - level) / 2.0
    return (float(stats.binom.ppf(tail, runs, nominal) / runs), float(stats.binom.ppf(1.0 - tail, runs, nominal) / runs))


def term_axis(rows: list[dict[str, Any]], term: str, axis: int, nominal: float) -> dict[str, Any]:
    """The statistics of one term on one axis over the done runs ``rows`` (one sweep point: one truth)."""
    truth = rows[0].get(f"{TRUTH}.{term}.{axis}") or 0.0
    sensor, key = term.split(".")
    found = [row for row in rows if row.get(f"{term}.{axis}") is not None]
    out: dict[str, Any] = {"truth": truth, "resolved": len(found), "unresolved": len(rows) - len(found)}
    if not truth > 0.0 or not found:
        return out
    values = np.array([row[f"{term}.{axis}"] for row in found], dtype=float)
    bounded = [row for row in rows if row.get(f"ci.{sensor}.{key}.upper.{axis}") is not None]
    lower, upper = (np.array([row[f"ci.{sensor}.{key}.{side}.{axis}"] for row in bounded], dtype=float)
                    for side in ("lower", "upper"))
    covered = int(np.sum((lower <= truth) & (truth <= upper)))
    low, high = coverage_band(len(bounded), nominal)
    coverage = covered / len(bounded)
    return {**out, "mean": float(values.mean()), "std": float(values.std(ddof=1)) if len(found) > 1 else None,
            "relative_error_mean": float(np.mean(values / truth - 1.0)), "intervals": len(bounded),
            "covered": covered, "coverage": coverage, "coverage_band": [low, high],
            "coverage_inside": bool(low <= coverage <= high)}


def point_summary(point: int, values: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The summary of one sweep point's rows: every term the config puts in, per axis; ``coverage_consistent``
    when every coverage lies in its band."""
    done = [row for row in rows if row.get(ERROR) is None]
    out: dict[str, Any] = {"point": point, "values": values, "runs": len(rows), "failed": len(rows) - len(done),
                           "done": len(done)}
    if not done:
        return out
    nominal = float(done[0][CI_LEVEL])
    terms = {term: [term_axis(done, term, k, nominal) for k in range(AXES)] for term in TERM_KEYS}
    tested = [a for per_axis in terms.values() for a in per_axis if "coverage" in a]
    above = sum(a["coverage"] > a["coverage_band"][1] for a in tested)
    below = sum(a["coverage"] < a["coverage_band"][0] for a in tested)
    return {**out, "ci_level": nominal, "terms": terms, "coverage_tested": len(tested), "coverage_above": above,
            "coverage_below": below, "coverage_consistent": bool(tested) and above == below == 0}


def _joined(texts: list[str]) -> str:
    return "/".join(dict.fromkeys(texts))


def point_lines(p: dict[str, Any]) -> list[str]:
    """The console lines of a point: whether its coverages are consistent with the intervals' level, then per
    term with a truth the relative error and the coverage per axis."""
    label = entry_label(p)
    if "terms" not in p:
        return [f"  {label}: no run done"]
    head = f"  {label}: {p['done']} runs, coverage of the {p['ci_level']:.1%} intervals"
    if p["coverage_consistent"]:
        lines = [f"{head} consistent with their level on all {p['coverage_tested']} terms and axes"]
    else:
        lines = [(f"{head} NOT consistent with their level: of {p['coverage_tested']} terms and axes, "
                 f"{p['coverage_above']} above their band (too wide), {p['coverage_below']} below (too narrow)")]
    for term, per_axis in p["terms"].items():
        shown = [a for a in per_axis if "coverage" in a]
        if not shown:
            continue
        error = " ".join(f"{a['relative_error_mean']:+.1%}" if "coverage" in a else "–" for a in per_axis)
        coverage = " ".join(f"{a['coverage']:.2f}" if "coverage" in a else "–" for a in per_axis)
        truth = _joined([f"{a['truth']:.4g}" for a in shown])
        band = _joined([f"{a['coverage_band'][0]:.2f}-{a['coverage_band'][1]:.2f}" for a in shown])
        lines.append(f"    {term} (truth {truth}): mean relative error {error}, coverage {coverage} (band {band})")
    return lines
