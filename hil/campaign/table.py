"""``OUT/runs.parquet``: one row a run, ordered by (point, run, unit), whatever order the runs completed in."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from hil.campaign.runs import row_order
from hil.config import InputError

RUNS_NAME = "runs.parquet"


class TableError(InputError, ValueError):
    """A runs.parquet that cannot be read for ``--resume``."""


def to_table(rows: list[dict[str, Any]]) -> pa.Table:
    """The rows sorted by (point, run, unit: a units config's); the columns in their first appearance, a missing
    value null."""
    rows = sorted(rows, key=row_order)
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    return pa.table({c: pa.array([row.get(c) for row in rows]) for c in columns})


def write_runs(out: Path, rows: list[dict[str, Any]]) -> Path:
    """Write ``out/runs.parquet`` whole, through a temporary file: a reader never sees half a table."""
    path = out / RUNS_NAME
    tmp = path.with_suffix(".parquet.tmp")
    pq.write_table(to_table(rows), tmp)
    os.replace(tmp, path)
    return path


def read_runs(out: Path) -> list[dict[str, Any]]:
    """The rows of ``out/runs.parquet`` (none when there is no table yet)."""
    path = out / RUNS_NAME
    if not path.exists():
        return []
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise TableError(f"{path}: cannot read: {' '.join(str(exc).split())}") from None
    return table.to_pylist()
