"""Turn-on-to-turn-on bias repeatability per unit: the sample standard deviation, per axis, of the accelerometer
bias estimated by the completed swings of a ``repeat`` block that power-cycles the unit, with its 95 % chi-square
interval (n - 1 degrees of freedom), beside the in-run sigma (the estimates' own mean 1-sigma)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from scipy.stats import chi2

from hil.plan.spec import Plan
from hil.plan.state import PlanState

CONFIDENCE = 0.95
DEFAULT_UNIT = "imu"  # the unit of a one-unit config without a serial number


def power_cycled_swings(plan: Plan, state: PlanState) -> list[dict[str, Any]]:
    """result.json of each completed swing in a repeat block that holds a power cycle, in order."""
    cycled = {step.block for step in plan.steps if step.block and step.kind == "power" and step.params == "cycle"}
    results = []
    for step in plan.steps:
        entry = state.entry(step)
        if step.kind == "swing" and step.block in cycled and entry["ended"] == "completed":
            results.append(json.loads((state.out / step.out_name / "result.json").read_text(encoding="utf-8")))
    return results


def repeatability(biases: np.ndarray, sigmas: np.ndarray) -> dict[str, Any]:
    """Per axis from ``biases`` (n x 3, ug) and their 1-sigmas: the turn-on repeatability, its interval, the
    in-run sigma and n."""
    n = len(biases)
    spread = np.std(biases, axis=0, ddof=1)
    dof = n - 1
    low = spread * np.sqrt(dof / chi2.ppf(0.5 + CONFIDENCE / 2, dof))
    high = spread * np.sqrt(dof / chi2.ppf(0.5 - CONFIDENCE / 2, dof))
    return {"turn_on_repeatability_ug": spread.tolist(),
            "turn_on_repeatability_ci_ug": [[float(a), float(b)] for a, b in zip(low, high)],
            "confidence": CONFIDENCE, "power_ons": n, "in_run_sigma_ug": np.mean(sigmas, axis=0).tolist(),
            "biases_ug": biases.tolist()}


def units_figures(plan: Plan, state: PlanState) -> dict[str, Any]:
    """plan.json ``units``: each unit's repeatability, where two or more power-cycled swings completed."""
    swings = power_cycled_swings(plan, state)
    if len(swings) < 2:
        return {}
    biases = np.array([doc["estimate"]["accel_bias_ug"] for doc in swings], dtype=float)
    sigmas = np.array([doc["estimate"]["accel_bias_sigma_ug"] for doc in swings], dtype=float)
    figures = repeatability(biases, sigmas)
    truth = [(doc.get("truth") or {}).get("accel_bias_ug") for doc in swings]
    if all(truth):  # emulated: the biases the unit had, and the spread they were drawn with
        figures["truth_biases_ug"] = truth
        figures["truth_turn_on_bias_ug"] = list(plan.config.imu.errors.turn_on_bias_ug)
    name = next((doc["record"].get("dut_serial") for doc in swings if doc.get("record")), None) or DEFAULT_UNIT
    return {name: figures}
