"""The entries of a campaign's summary: its sweep points, or in a campaign of a units config (docs/units.md) each
sweep point's units, an entry each: which rows are an entry's, and how it is labelled (``unit=<name>`` first)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from hil.campaign.runs import UNIT
from hil.campaign.task import RunTask, point_label

Entry = tuple[int, str | None]  # (point, unit), the unit None in a one-unit campaign


def summary_entries(tasks: Iterable[RunTask]) -> list[Entry]:
    """Every (point, unit) of the tasks, in their order."""
    return list(dict.fromkeys((task.point, task.unit) for task in tasks))


def row_entry(row: dict[str, Any]) -> Entry:
    return row["point"], row.get(UNIT)


def with_unit(summary: dict[str, Any], unit: str | None) -> dict[str, Any]:
    """A point's summary as its unit's entry: ``unit`` after ``point`` (none in a one-unit campaign)."""
    return summary if unit is None else {"point": summary["point"], UNIT: unit, **summary}


def entry_rows(rows: list[dict[str, Any]], p: dict[str, Any]) -> list[dict[str, Any]]:
    """The rows of the summary entry ``p``."""
    return [row for row in rows if row_entry(row) == (p["point"], p.get(UNIT))]


def entry_values(p: dict[str, Any]) -> dict[str, Any]:
    """What labels the summary entry ``p``: its unit, then its sweep point's values."""
    return {UNIT: p[UNIT], **p["values"]} if UNIT in p else p["values"]


def entry_label(p: dict[str, Any]) -> str:
    return point_label(entry_values(p))
