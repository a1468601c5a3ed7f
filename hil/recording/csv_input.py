"""Increments as CSV (docs/contracts.md, "CSV of increments"): read those exported from other acquisition software, and
write a trial's own."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from hil.config import Config, InputError, LimitsConfig
from hil.frames import Earth
from hil.pipeline.plausibility import RATE_MARGIN, ImuPlausibility
from hil.samples import AlignedBatch
from hil.units import DEG, G0

INCREMENT_COLUMNS = ("t_s", "dtheta_x_rad", "dtheta_y_rad", "dtheta_z_rad", "dv_x_mps", "dv_y_mps", "dv_z_mps")
ANGLE_COLUMNS = ("outer_deg", "middle_deg", "inner_deg")


class DataError(InputError, ValueError):
    """Input data that cannot be used; the message names the file, line and reason."""

    @classmethod
    def unreadable(cls, path: str | Path, exc: OSError) -> DataError:
        """The error for a file the disk would not give (not its content), in one line."""
        return cls(f"{path}: cannot read: {exc.strerror or exc}")


def read_increments_csv(path: str | Path, cfg: Config | None = None) -> AlignedBatch:
    """Rows of increments (each covering the interval that ends at t_s) and, if present, table angles. Increments
    beyond what an IMU on ``cfg``'s turntable can measure are refused like malformed ones
    (:func:`refuse_implausible`)."""
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
        rows, lines = [], []
        for line_no, row in enumerate(reader, start=2):
            if not row or all(not cell.strip() for cell in row):
                continue
            try:
                values = [float(row[i]) for i in index]
            except (ValueError, IndexError):
                raise DataError(f"{path}:{line_no}: expected numbers in columns {', '.join(wanted)}") from None
            if not np.all(np.isfinite(values)):
                bad = int(np.argmin(np.isfinite(values)))
                raise DataError(f"{path}:{line_no}: {wanted[bad]} {values[bad]} is not finite")
            if rows and values[0] <= rows[-1][0]:
                raise DataError(f"{path}:{line_no}: t_s {values[0]} is not after the previous row's {rows[-1][0]}")
            rows.append(values)
            lines.append(line_no)
    if len(rows) < 2:
        raise DataError(f"{path}: needs at least two data rows, got {len(rows)}")
    data = np.array(rows)
    refuse_implausible(path, data, lines, cfg)
    t = data[:, 0]
    angles = data[:, 7:10] * DEG if has_angles else None
    return AlignedBatch(t, data[:, 1:4], data[:, 4:7], angles, t0=float(t[0] - (t[1] - t[0])))


def refuse_implausible(path: Path, data: np.ndarray, lines: list[int], cfg: Config | None) -> None:
    """Raises :class:`DataError` naming the first row (line, column, value) that no IMU on ``cfg``'s turntable gives:
    increments the live trial's plausibility check would reject (:func:`_implausible_increments`), else table angles
    that turn faster than the table can (:func:`_implausible_angles`). Without ``cfg``, standard gravity and the
    default rate limits."""
    limits = (cfg.turntable.limits if cfg else LimitsConfig()).rate_dps
    gravity = Earth.from_config(cfg.site).g if cfg else G0
    problem = _implausible_increments(data, limits, gravity)
    if problem is None and data.shape[1] > len(INCREMENT_COLUMNS):
        problem = _implausible_angles(data, limits)
    if problem is not None:
        k, where, reason = problem
        raise DataError(f"{path}:{lines[k]}: {where} is physically implausible: {reason}")


def _implausible_increments(data: np.ndarray, limits: tuple[float, ...], gravity: float
                            ) -> tuple[int, str, str] | None:
    """(row, column and value, reason) of the first row whose increments
    :class:`~hil.pipeline.plausibility.ImuPlausibility` rejects over the file's sample interval (the median spacing
    of t_s, which a gap does not change): a rotation faster than the table's rate limits allow, or a specific force
    not near gravity."""
    period = float(np.median(np.diff(data[:, 0])))
    check = ImuPlausibility(1.0 / period, gravity, RATE_MARGIN * max(limits) * DEG)
    with np.errstate(over="ignore", invalid="ignore"):  # 1e308 squared is inf: implausible, not a warning
        good = check.ok(data[:, 1:4], data[:, 4:7])
        if good.all():
            return None
        k = int(np.argmin(good))
        check.ok(data[k:k + 1, 1:4], data[k:k + 1, 4:7])
    force_g, rate = check.last_rejected
    if rate > 1.0:
        where = _largest(data[k], 1)
        reason = f"a rotation {rate:.3g} times the fastest the table allows ({RATE_MARGIN:g} x {max(limits):g} deg/s)"
    else:
        where = _largest(data[k], 4) if force_g > 1.0 else "dv_x_mps, dv_y_mps, dv_z_mps"
        reason = f"a specific force of {force_g:.3g} g, not within {check.force_tolerance / gravity:g} g of gravity"
    return k, where, f"{reason} over the {period:.6g} s sample interval"


def _implausible_angles(data: np.ndarray, limits: tuple[float, ...]) -> tuple[int, str, str] | None:
    """(row, column and value, reason) of the first row whose table angle turned since the row before (the
    shorter way round: angles may be wrapped) further than its gimbal's rate limit, with the plausibility check's
    margin, allows in their interval."""
    interval = np.diff(data[:, 0])
    with np.errstate(over="ignore", invalid="ignore"):  # an absurd angle's difference may overflow: implausible
        turn = np.abs((np.diff(data[:, 7:10], axis=0) + 180.0) % 360.0 - 180.0)
        good = turn <= RATE_MARGIN * np.asarray(limits) * interval[:, None]
    if good.all():
        return None
    k, axis = (int(i) for i in np.argwhere(~good)[0])
    return (k + 1, f"{ANGLE_COLUMNS[axis]} {float(data[k + 1, 7 + axis])!r}",
            f"a turn of {turn[k, axis]:.3g} deg in the {interval[k]:.6g} s since the row before, beyond the "
            f"{RATE_MARGIN:g} x {limits[axis]:g} deg/s the table allows")


def _largest(row: np.ndarray, first: int) -> str:
    """The column of the largest magnitude among the three from ``first``, and its value."""
    column = first + int(np.argmax(np.abs(row[first:first + 3])))
    return f"{INCREMENT_COLUMNS[column]} {float(row[column])!r}"


def write_increments_csv(path: Path, batch: AlignedBatch) -> None:
    """The increments (and table angles) in the CSV layout ``hil estimate`` and ``hil noise`` read, every
    number written exactly (shortest repr that reads back to the same float)."""
    header = INCREMENT_COLUMNS + (ANGLE_COLUMNS if batch.angles is not None else ())
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        columns = [batch.t[:, None], batch.dtheta, batch.dv] + ([batch.angles / DEG] if batch.angles is not None else [])
        writer.writerows([repr(float(v)) for v in row] for row in np.hstack(columns))
