"""One run of a campaign as a worker takes it, and the label of a sweep point."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class RunTask:
    """One run as a worker takes it: small and picklable (the config as a mapping, not a model). In a campaign of
    a units config (docs/units.md) each run is a task per unit: ``config`` is the unit's one-unit config."""

    id: str
    point: int
    run: int
    seed: int  # the run's trial.seed (of a units config: each unit's own is drawn from it)
    values: dict[str, Any]  # the swept values of its point, by dotted key
    config: dict  # the base config with the point's values and trial.seed set
    unit: str | None = None  # the unit's name, in a campaign of a units config


def point_label(values: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in values.items()) or "base"
