"""SI values as the micro-g units of the outputs (result.json, series.csv)."""

from __future__ import annotations

import numpy as np

from hil.units import HOUR, UG


def to_ug(v: np.ndarray | None) -> list[float] | None:
    """m/s^2 as micro-g."""
    return None if v is None else [float(x) for x in np.asarray(v) / UG]


def to_ug_per_h(v: np.ndarray | None) -> list[float] | None:
    """m/s^3 as micro-g per hour."""
    return None if v is None else [float(x) for x in np.asarray(v) / UG * HOUR]
