"""series.csv: the estimates over time, one row per snapshot (column names carry the units), with the IMU's
temperature where its frames report one."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hil.outputs.conversions import to_ug, to_ug_per_h
from hil.units import DEG

if TYPE_CHECKING:  # the figure process reads series without the estimator's modules
    from hil.estimation.online import Snapshot

SERIES_NAME = "series.csv"
SERIES_COLUMNS = (
    "t_s", "samples",
    "bias_x_ug", "bias_y_ug", "bias_z_ug", "sigma_x_ug", "sigma_y_ug", "sigma_z_ug",
    "observable", "gram_rank", "gram_condition", "gram_rank_9",
    "method1_pitch_deg", "method1_roll_deg", "method1_yaw_deg",
    "method2_pitch_deg", "method2_roll_deg", "method2_yaw_deg",
    "theoretical_pitch_deg", "theoretical_roll_deg",
    "drift_x_ug_per_h", "drift_y_ug_per_h", "drift_z_ug_per_h",
    "drift_sigma_x_ug_per_h", "drift_sigma_y_ug_per_h", "drift_sigma_z_ug_per_h", "temperature_c",
)  # fmt: skip


def series_rows(snapshots: list[Snapshot], temperatures: Mapping[float, float] | None = None
                ) -> list[list[float | int | str]]:
    """One row per snapshot, in SERIES_COLUMNS order (empty cells where a value does not exist); the temperature
    (deg C) is ``temperatures``' at the snapshot's time, NaN where it has none."""
    temperatures = temperatures or {}
    nan3 = [float("nan")] * 3
    rows = []
    for s in snapshots:
        bias = to_ug(s.full.bias) or nan3
        sigma = to_ug(s.full.bias_sigma) or nan3
        m1 = list(s.error_method1 / DEG) if s.error_method1 is not None else nan3
        m2 = list(s.error_method2 / DEG) if s.error_method2 is not None else nan3
        theo = list(s.error_theoretical / DEG) if s.error_theoretical is not None else nan3[:2]
        drift = to_ug_per_h(s.drift_check.drift) if s.drift_check is not None else nan3
        drift_sigma = to_ug_per_h(s.drift_check.sigma) if s.drift_check is not None else nan3
        obs = s.full.observability
        rows.append(
            [s.t, s.samples, *bias, *sigma, int(s.full.observable), obs.rank, obs.condition,
             s.gravity_only.observability.rank, *m1, *m2, *theo, *drift, *drift_sigma,
             temperatures.get(float(s.t), math.nan)]
        )  # fmt: skip
    return rows


def write_series(out: Path, snapshots: list[Snapshot], temperatures: Mapping[float, float] | None = None
                 ) -> np.ndarray:
    """Write ``out/series.csv`` (empty cells where a value does not exist); returns the rows as an array
    (NaN for the empty cells), in SERIES_COLUMNS order."""
    rows = series_rows(snapshots, temperatures)
    with open(out / SERIES_NAME, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(SERIES_COLUMNS)
        writer.writerows(["" if v != v else v for v in row] for row in rows)  # v != v: NaN, a cell that does not exist
    return np.array(rows, dtype=float).reshape(-1, len(SERIES_COLUMNS))


def read_series(path: Path) -> dict[str, np.ndarray] | None:
    """The columns of a series.csv by name (NaN for empty cells); None when there is no row."""
    if not path.exists():
        return None
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2:
        return None
    header, body = rows[0], rows[1:]
    data = np.array([[float(v) if v != "" else np.nan for v in row] for row in body])
    return {name: data[:, k] for k, name in enumerate(header)}


