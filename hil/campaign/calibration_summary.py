"""summary.json of a calibration campaign: per sweep point and calibrated term (``accel.bias_ug.0``, ...,
``turntable.zero_offset_arcsec.1``, in calibration.json's units), whether the scatter of its error over the
runs matches the sigma the calibration reports.

With e the error (estimate minus the truth as the schedule observes it) of the M runs that judge the term,
sigma their reported 1-sigma and z their error in sigmas (hil/outputs/calibration_report.py ``comparison``:
an angle's sigma with the encoder's resolution): the mean and std (M - 1 degrees of freedom) of e, the mean
sigma, the ratio ``r = std(e) / mean(sigma)`` with the chi-square band of a consistent estimator
(:func:`hil.campaign.swing_summary.ratio_band`), the fraction of runs with ``|z| <= 3`` (0.9973 for a consistent
one) and the RMS of z (1). A run that reports the term unobservable counts in ``unobservable``, not in M.
Per family (the axes of a term) the range of the ratios, and the fraction within 3 sigma and the RMS of z
over all its runs. The point's headline: how many of the n terms with a ratio have it outside its band
(``ratio_above``, ``ratio_below``). Each lies outside with probability 0.05 for a consistent calibration,
so ``ratio_expected_outside`` is 0.05 n, and for independent terms their count K ~ Binomial(n, 0.05):
``consistent`` when K is at most ``ratio_outside_allowed``, its 95 % quantile (the terms are correlated,
which widens K's distribution: a count just above it is weak evidence). ``worst``: the term whose ratio is
farthest from 1 (by its logarithm).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

from hil.campaign.entries import entry_label
from hil.campaign.runs import ERROR, TERM
from hil.campaign.swing_summary import LEVEL, ratio_band

WITHIN = 3.0  # sigmas


def term_names(rows: list[dict[str, Any]]) -> list[str]:
    """The terms of the rows' columns (``term.<name>.estimate``), in the order they first appear."""
    prefix, suffix = f"{TERM}.", ".estimate"
    return list(dict.fromkeys(k[len(prefix):-len(suffix)] for row in rows for k in row
                              if k.startswith(prefix) and k.endswith(suffix)))


def term_statistics(rows: list[dict[str, Any]], term: str) -> dict[str, Any]:
    """The statistics of one term over the done runs ``rows`` of a sweep point (module docstring)."""
    key = f"{TERM}.{term}"
    judged = [row for row in rows if row.get(f"{key}.error_sigma") is not None]
    out: dict[str, Any] = {"runs": len(judged), "unobservable": len(rows) - len(judged)}
    if not judged:
        return out
    estimate, truth, sigma, z = (np.array([row[f"{key}.{field}"] for row in judged], dtype=float)
                                 for field in ("estimate", "truth", "sigma", "error_sigma"))
    error = estimate - truth
    out.update(error_mean=float(error.mean()), sigma_mean=float(sigma.mean()),
               within_3sigma=float(np.mean(np.abs(z) <= WITHIN)), z_rms=float(np.sqrt(np.mean(z**2))))
    if len(judged) < 2 or not out["sigma_mean"] > 0.0:
        return out
    std = float(error.std(ddof=1))
    low, high = ratio_band(len(judged))
    ratio = std / out["sigma_mean"]
    return {**out, "error_std": std, "ratio": ratio, "ratio_band": [low, high], "ratio_inside": low <= ratio <= high}


def family_statistics(terms: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per family of terms (``accel.bias_ug``: its three axes) over the terms with a ratio: how many, the
    smallest and largest ratio, and the fraction within 3 sigma and the RMS of z over all their runs."""
    families: dict[str, list[dict[str, Any]]] = {}
    for term, s in terms.items():
        if "ratio" in s:
            families.setdefault(term.rsplit(".", 1)[0], []).append(s)
    out = {}
    for family, members in families.items():
        runs = np.array([s["runs"] for s in members], dtype=float)
        out[family] = {"terms": len(members), "ratio_min": min(s["ratio"] for s in members),
                       "ratio_max": max(s["ratio"] for s in members),
                       "within_3sigma": float(np.sum(runs * [s["within_3sigma"] for s in members]) / runs.sum()),
                       "z_rms": float(np.sqrt(np.sum(runs * [s["z_rms"] ** 2 for s in members]) / runs.sum()))}
    return out


def point_summary(point: int, values: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The summary of one sweep point's rows: every term's statistics and the point's headline."""
    done = [row for row in rows if row.get(ERROR) is None]
    out: dict[str, Any] = {"point": point, "values": values, "runs": len(rows), "failed": len(rows) - len(done),
                           "done": len(done)}
    if not done:
        return out
    terms = {term: term_statistics(done, term) for term in term_names(done)}
    tested = {term: s for term, s in terms.items() if "ratio" in s}
    above = sum(s["ratio"] > s["ratio_band"][1] for s in tested.values())
    below = sum(s["ratio"] < s["ratio_band"][0] for s in tested.values())
    allowed = int(stats.binom.ppf(LEVEL, len(tested), 1.0 - LEVEL))
    worst = max(tested, key=lambda term: abs(math.log(tested[term]["ratio"]) if tested[term]["ratio"] > 0
                                             else math.inf), default=None)
    return {**out, "terms": terms, "families": family_statistics(terms), "ratio_tested": len(tested),
            "ratio_above": above, "ratio_below": below,
            "ratio_expected_outside": (1.0 - LEVEL) * len(tested), "ratio_outside_allowed": allowed,
            "consistent": bool(tested) and above + below <= allowed,
            "worst": None if worst is None else {"term": worst, **{k: tested[worst][k] for k in
                                                                    ("ratio", "ratio_band", "within_3sigma")}}}


def point_lines(p: dict[str, Any]) -> list[str]:
    """The console lines of a point: the headline, each family's ratios, the terms outside their band and the
    unobservable ones."""
    label = entry_label(p)
    if "terms" not in p:
        return [f"  {label}: no run done"]
    if not p["ratio_tested"]:
        return [f"  {label}: {p['done']} runs done: too few for statistics"]
    head = f"  {label}: {p['done']} runs, std(error)/mean(sigma) of {p['ratio_tested']} terms"
    worst = p["worst"]
    lines = [(f"{head} {'consistent' if p['consistent'] else 'NOT consistent'}: {p['ratio_above']} above, "
              f"{p['ratio_below']} below their 95 % band (by chance ~{p['ratio_expected_outside']:.1f}, at most "
              f"{p['ratio_outside_allowed']}); worst {worst['term']} {worst['ratio']:.3f} "
              f"(band {worst['ratio_band'][0]:.3f}-{worst['ratio_band'][1]:.3f})")]
    for family, f in p["families"].items():
        lines.append(f"    {family}: std(error)/mean(sigma) {f['ratio_min']:.3f}-{f['ratio_max']:.3f} over "
                     f"{f['terms']} terms, within 3 sigma {f['within_3sigma']:.2f}, rms error/sigma {f['z_rms']:.2f}")
    for term, s in p["terms"].items():
        if "ratio" in s and not s["ratio_inside"]:
            lines.append(f"    outside its band: {term} {s['ratio']:.3f} ({s['ratio_band'][0]:.3f}-"
                         f"{s['ratio_band'][1]:.3f}), within 3 sigma {s['within_3sigma']:.2f}, rms error/sigma "
                         f"{s['z_rms']:.2f}")
        elif s["unobservable"]:
            lines.append(f"    {term}: unobservable in {s['unobservable']} of {p['done']} runs")
    return lines
