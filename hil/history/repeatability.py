"""A unit's run-to-run figures from its history rows: the 2018 gravity-vector paper's bias repeatability, the
sample standard deviation of the accelerometer bias over the unit's completed swing trials, with its
chi-square confidence interval, beside the mean within-run sigma (docs/history.md, "Repeatability")."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.stats import chi2

from hil.history.entry import SWING

LEVEL = 0.95  # the confidence interval's level


def completed_swings(trials: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The completed swing trials that estimated a bias."""
    return [t for t in trials if t["kind"] == SWING and t["ended"] == "completed"
            and t["figures"].get("accel_bias_ug") is not None and None not in t["figures"]["accel_bias_ug"]]


def repeatability(biases: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(std over runs (ddof 1), its [lo, hi] interval per axis) of ``biases`` (runs, 3); None below 2 runs.

    (n - 1) s^2 / sigma^2 is chi-square with n - 1 degrees of freedom, so sigma lies in
    [s sqrt((n-1) / chi2_hi), s sqrt((n-1) / chi2_lo)] at the level :data:`LEVEL`."""
    n = len(biases)
    if n < 2:
        return None
    s = biases.std(axis=0, ddof=1)
    lo, hi = chi2.ppf([(1 + LEVEL) / 2, (1 - LEVEL) / 2], n - 1)
    return s, np.stack([s * np.sqrt((n - 1) / lo), s * np.sqrt((n - 1) / hi)], axis=1)


def unit_summary(dut_serial: str | None, trials: list[dict[str, Any]]) -> dict[str, Any]:
    """``hil history --json``'s document (docs/contracts.md, "hil history --json")."""
    swings = completed_swings(trials)
    biases = np.array([t["figures"]["accel_bias_ug"] for t in swings], dtype=float).reshape(-1, 3)
    found = repeatability(biases)
    sigmas = [t["figures"].get("accel_bias_sigma_ug") for t in swings]
    within = np.mean(np.array(sigmas, dtype=float), axis=0).tolist() if swings and None not in sigmas else None
    return {"dut_serial": dut_serial, "runs": len(swings),
            "accel_bias_repeatability_ug": None if found is None else found[0].tolist(),
            "accel_bias_repeatability_ci_ug": None if found is None else found[1].tolist(),
            "accel_bias_within_run_sigma_ug": within, "accel_bias_mean_ug": biases.mean(axis=0).tolist() if swings else None,
            "trials": trials}
