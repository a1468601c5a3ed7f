"""Increments as CSV (docs/contracts.md, "CSV of increments"): read those exported from other acquisition software, and
write a trial's own."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from hil.config import InputError
from hil.samples import AlignedBatch
from hil.units import DEG

INCREMENT_COLUMNS = ("t_s", "dtheta_x_rad", "dtheta_y_rad", "dtheta_z_rad", "dv_x_mps", "dv_y_mps", "dv_z_mps")
ANGLE_COLUMNS = ("outer_deg", "middle_deg", "inner_deg")


class DataError(InputError, ValueError):
    """Input data that cannot be used; the message names the file, line and reason."""

    @classmethod
    def unreadable(cls, path: str | Path, exc: OSError) -> DataError:
        """The error for a file the disk would not give (not its content), in one line."""
        return cls(f"{path}: cannot read: {exc.strerror or exc}")


def read_increments_csv(path: str | Path) -> AlignedBatch:
    """Rows of increments (each covering the interval that ends at t_s) and, if present, table angles."""
    path = Path(path)
    try:
        fh = open(path, newline="", encoding="utf-8")
    except OSError as exc:
        raise DataError.unreadable(path, exc) from None
    with fh:
        reader = csv.reader(fh)
        header = [h.strip() for h in next(reader, [])]
        missing = [c for c in INCREMENT_COLUMNS if c not in header]
        if missing:
            raise DataError(f"{path}: header lacks required column(s) {', '.join(missing)}")
        has_angles = all(c in header for c in ANGLE_COLUMNS)
        wanted = INCREMENT_COLUMNS + (ANGLE_COLUMNS if has_angles else ())
        index = [header.index(c) for c in wanted]
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if not row or all(not cell.strip() for cell in row):
                continue
            try:
                values = [float(row[i]) for i in index]
            except (ValueError, IndexError):
                raise DataError(f"{path}:{line_no}: expected numbers in columns {', '.join(wanted)}") from None
            if not np.all(np.isfinite(values)):
                raise DataError(f"{path}:{line_no}: value is not finite")
            if rows and values[0] <= rows[-1][0]:
                raise DataError(f"{path}:{line_no}: t_s {values[0]} is not after the previous row's {rows[-1][0]}")
            rows.append(values)
    if len(rows) < 2:
        raise DataError(f"{path}: needs at least two data rows, got {len(rows)}")
    data = np.array(rows)
    t = data[:, 0]
    angles = data[:, 7:10] * DEG if has_angles else None
    return AlignedBatch(t, data[:, 1:4], data[:, 4:7], angles, t0=float(t[0] - (t[1] - t[0])))


def write_increments_csv(path: Path, batch: AlignedBatch) -> None:
    """The increments (and table angles) in the CSV layout ``hil estimate`` and ``hil noise`` read, every
    number written exactly (shortest repr that reads back to the same float)."""
    header = INCREMENT_COLUMNS + (ANGLE_COLUMNS if batch.angles is not None else ())
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        columns = [batch.t[:, None], batch.dtheta, batch.dv] + ([batch.angles / DEG] if batch.angles is not None else [])
        writer.writerows([repr(float(v)) for v in row] for row in np.hstack(columns))
