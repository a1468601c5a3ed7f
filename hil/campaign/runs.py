"""One run of a campaign, as a worker executes it, flattened into one row of runs.parquet: the simulated trial
of ``hil simulate`` and its result.json document (kind ``swing``), or the simulated static trial of
``hil noise CONFIG`` and its noise.json document with the noise terms the config puts in (kind ``noise``), or
the simulated calibration trial of ``hil calibrate --simulate`` with its terms against the truth (kind
``calibration``).
No outputs are written, no viewer opened. Each kind's function imports its trial's modules when it first runs:
the client imports this module only to send the functions by reference, and a worker loads the one kind its
campaign runs (a swing campaign never loads the servo or the calibration fit)."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import yaml

from hil.campaign.task import RunTask

SWEEP_PREFIX = "sweep."  # a swept value's column: sweep.<dotted key> (result.json has trial.* keys of its own)
ERROR = "error"
UNIT = "unit"  # the unit's name: a column of a units config's campaign only


def flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    """Every scalar of a nested document under its dotted path; list items by index (``a.b.0``); a
    non-finite float as None, as result.json writes it."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in flatten(item, f"{prefix}{key}.").items()}
    if isinstance(value, (list, tuple)):
        return {k: v for i, item in enumerate(value) for k, v in flatten(item, f"{prefix}{i}.").items()}
    if isinstance(value, float) and not math.isfinite(value):
        value = None
    elif hasattr(value, "item"):  # a numpy scalar
        value = value.item()
    return {prefix[:-1]: value}


def task_columns(task: RunTask) -> dict[str, Any]:
    """The columns every row of the task has, done or failed: its id, indices (and unit, of a units config), seed,
    swept values and its part of the record (the device of its config's ``record`` block, the SHA-256 of the config
    text the run was given)."""
    record = task.config.get("record") or {}
    digest = hashlib.sha256(yaml.safe_dump(task.config).encode()).hexdigest()
    unit = {} if task.unit is None else {UNIT: task.unit}
    return {"id": task.id, "point": task.point, "run": task.run, **unit, "seed": task.seed,
            **flatten(task.values, SWEEP_PREFIX), "record.dut_part": record.get("dut_part"),
            "record.dut_serial": record.get("dut_serial"), "record.config_sha256": digest}


def row_order(row: dict[str, Any]) -> tuple[int, int, str]:
    """A row's place among a campaign's: by point, run and unit (a units config's), whatever order the runs
    completed in."""
    return row["point"], row["run"], row.get(UNIT) or ""


def failed_row(task: RunTask, error: BaseException | str) -> dict[str, Any]:
    text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    return {**task_columns(task), ERROR: " ".join(text.split()) or "failed"}


def run_swing(task: RunTask) -> dict[str, Any]:
    """The row of one run: a simulated trial of the task's config; a run that raises is a row with ``error``."""
    from hil.config import parse_config
    from hil.trial.offline import run_simulation
    from hil.trial.viewer_feed import ViewerOptions

    try:
        cfg = parse_config(task.config, task.id)
        outcome, _ = run_simulation(cfg, yaml.safe_dump(task.config), Path("."), ViewerOptions("none"))
    except Exception as exc:  # noqa: BLE001 - a failed run is a row, never a lost campaign
        return failed_row(task, exc)
    return {**task_columns(task), ERROR: None, **flatten(outcome.result)}


TRUTH = "truth"  # a noise run's configured terms: truth.<sensor>.<noise.json key>.<axis>


def run_noise(task: RunTask) -> dict[str, Any]:
    """The row of one noise run: the Allan analysis of the task's simulated static trial, and the truth."""
    from hil.config import parse_config
    from hil.trial.noise_runner import analyse_record, noise_truth, simulated

    try:
        cfg = parse_config(task.config, task.id)
        doc = analyse_record(simulated(cfg), task.id).doc
    except Exception as exc:  # noqa: BLE001 - a failed run is a row, never a lost campaign
        return failed_row(task, exc)
    return {**task_columns(task), ERROR: None, **flatten(doc), **flatten(noise_truth(cfg.imu.errors, cfg.imu_rate_hz),
                                                                        f"{TRUTH}.")}


TERM = "term"  # a calibration run's terms: term.<block>.<key>.<index>.{estimate,sigma,truth,error_sigma}
TERM_FIELDS = ("estimate", "sigma", "truth", "error_sigma")


def run_calibration(task: RunTask) -> dict[str, Any]:
    """The row of one calibration run: the simulated calibration trial of ``hil calibrate --simulate``, its
    result.json document and, per term of calibration.json, the estimate, its sigma, the truth as the
    schedule observes it and the error in sigmas (None for a term reported unobservable). A trial that
    ended without a calibration is a row with ``error``."""
    from hil.config import parse_config
    from hil.outputs.calibration_report import comparison
    from hil.trial.calibration_simulation import run_calibration_simulation

    try:
        cfg = parse_config(task.config, task.id)
        outcome, _ = run_calibration_simulation(cfg, yaml.safe_dump(task.config), Path("."))
    except Exception as exc:  # noqa: BLE001 - a failed run is a row, never a lost campaign
        return failed_row(task, exc)
    if outcome.calibration is None:
        return failed_row(task, f"trial {outcome.result['ended']}")
    terms = {f"{TERM}.{r['term']}.{field}": r[field] for r in comparison(outcome.calibration) for field in TERM_FIELDS}
    return {**task_columns(task), ERROR: None, **flatten(outcome.result), **flatten(terms)}
