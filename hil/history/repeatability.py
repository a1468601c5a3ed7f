"""A unit's run-to-run figures from its history rows: the 2018 gravity-vector paper's bias repeatability, the
sample standard deviation of the accelerometer bias over the unit's completed, observable, converged swing
trials, with its chi-square confidence interval, beside the mean within-run sigma; what it left out and why
(docs/history.md, "Repeatability")."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import chdtri  # chi2.ppf(q, k) = chdtri(k, 1 - q), without scipy.stats' 1-3 s import

from hil.history.entry import SWING

LEVEL = 0.95  # the confidence interval's level
# why a swing row is not one of its unit's runs, in the order they are asked (a row counts under its first);
# a row without a serial is a sound run of no known unit when no other reason applies
LEFT_OUT = ("replay", "not_completed", "not_observable", "not_converged", "no_serial")


def left_out_because(trial: dict[str, Any]) -> str | None:
    """Why the swing row ``trial`` is not a run of the repeatability (:data:`LEFT_OUT`); None when it is one."""
    figures = trial["figures"]
    bias = figures.get("accel_bias_ug")
    reasons = {"replay": trial.get("replay_of") is not None, "not_completed": trial["ended"] != "completed",
               "not_observable": figures.get("observable") is False or bias is None or None in bias,
               "not_converged": figures.get("converged_at_s") is None, "no_serial": trial["dut_serial"] is None}
    return next((reason for reason in LEFT_OUT if reasons[reason]), None)


def repeatability(biases: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(std over runs (ddof 1), its [lo, hi] interval per axis) of ``biases`` (runs, 3); None below 2 runs.

    (n - 1) s^2 / sigma^2 is chi-square with n - 1 degrees of freedom, so sigma lies in
    [s sqrt((n-1) / chi2_hi), s sqrt((n-1) / chi2_lo)] at the level :data:`LEVEL`."""
    n = len(biases)
    if n < 2:
        return None
    s = biases.std(axis=0, ddof=1)
    lo, hi = chdtri(n - 1, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])  # the upper, then the lower quantile
    return s, np.stack([s * np.sqrt((n - 1) / lo), s * np.sqrt((n - 1) / hi)], axis=1)


def unit_figures(dut_serial: str | None, trials: list[dict[str, Any]]) -> dict[str, Any]:
    """One unit's entry of ``hil history --json`` (docs/contracts.md) from its rows ``trials``: the runs, the
    repeatability over them, and the count of swing rows left out for each reason of :data:`LEFT_OUT`."""
    left_out = dict.fromkeys(LEFT_OUT, 0)
    runs = []
    for trial in (t for t in trials if t["kind"] == SWING):
        reason = left_out_because(trial)
        if reason is None:
            runs.append(trial)
        else:
            left_out[reason] += 1
    biases = np.array([t["figures"]["accel_bias_ug"] for t in runs], dtype=float).reshape(-1, 3)
    found = repeatability(biases)
    sigmas = [t["figures"].get("accel_bias_sigma_ug") for t in runs]
    within = np.mean(np.array(sigmas, dtype=float), axis=0).tolist() if runs and None not in sigmas else None
    return {"dut_serial": dut_serial, "runs": len(runs), "left_out": left_out,
            "accel_bias_repeatability_ug": None if found is None else found[0].tolist(),
            "accel_bias_repeatability_ci_ug": None if found is None else found[1].tolist(),
            "accel_bias_within_run_sigma_ug": within,
            "accel_bias_mean_ug": biases.mean(axis=0).tolist() if runs else None}


def history_summary(dut_serial: str | None, since: str | None, trials: list[dict[str, Any]]) -> dict[str, Any]:
    """``hil history --json``'s document (docs/contracts.md, "hil history --json"): one entry per unit (the
    unit asked, else every serial in ``trials``, the rows without one last), and the rows."""
    serials = [dut_serial] if dut_serial is not None else sorted({t["dut_serial"] for t in trials} - {None})
    if dut_serial is None and any(t["dut_serial"] is None for t in trials):
        serials.append(None)
    units = [unit_figures(serial, [t for t in trials if t["dut_serial"] == serial]) for serial in serials]
    return {"dut_serial": dut_serial, "since": since, "units": units, "trials": trials}
