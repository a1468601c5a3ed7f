"""``hil noise``: the Allan deviation and the IEEE noise terms of a trial's increments.

The source is a trial config (simulated, as ``hil simulate``), a run directory or recording (replayed
through the same decoding, alignment and gates as the live run) or a CSV of increments. A static trial
is analysed as it is (earth rate and gravity are constants, invisible to the Allan variance); on a
moving one the table's motion is first taken out with its angles (:mod:`hil.pipeline.table_motion`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.config import Config, load_config, resolve_path
from hil.estimation.allan import DEFAULT_LEVEL, analyse
from hil.frames import Earth, TableGeometry
from hil.recording.csv_input import DataError, read_increments_csv, write_increments_csv
from hil.samples import AlignedBatch
from hil.trial.outcome import TrialSetupError
from hil.units import DEG

STATIC_ANGLE_SPAN = 1e-3 * DEG  # table angles spanning less than this: a static trial
STATIC_RATE_SPAN = 0.5 * DEG  # rad/s: 1-s mean rates spanning more than this without angles: a moving IMU


@dataclass(frozen=True)
class NoiseRecord:
    """A trial's increments and what the analysis needs to know of the trial."""

    batch: AlignedBatch
    source: str  # "simulation", "recording" or "csv"
    cfg: Config | None  # the trial's config (site, table): --config, else the recorded or simulated one


def read_source(source: str | Path, config: str | Path | None = None) -> NoiseRecord:
    """The increments of ``source``: a config, a run directory or recording, or a CSV (with ``config`` for
    its site and table, needed when it moves)."""
    path = Path(source)
    given = None if config is None else load_config(config)
    if path.is_dir() or path.suffix == ".mcap":
        batch, recorded = _replayed(path)
        return NoiseRecord(batch, "recording", given or recorded)
    if path.suffix == ".csv":
        return NoiseRecord(read_increments_csv(path), "csv", given)
    from emulators.simulation import Simulation

    cfg = load_config(resolve_path(path))
    return NoiseRecord(_concatenated(list(Simulation.from_config(cfg).batches())), "simulation", cfg)


def _replayed(path: Path) -> tuple[AlignedBatch, Config]:
    """The samples the estimator took in a replay of the recording, and the recorded config."""
    from hil.pipeline.processor import TrialProcessor
    from hil.recording.replay import open_recording

    recording, cfg = open_recording(path)
    runs: list[tuple[np.ndarray, ...]] = []
    processor = TrialProcessor(cfg, on_samples=lambda *arrays: runs.append(arrays))
    for item in recording.items:
        processor.feed(item)
    processor.finish()
    if not runs:
        raise DataError(f"{path}: no IMU sample reached the estimator: nothing to analyse")
    t, dtheta, dv, angles = (np.concatenate(column) for column in zip(*runs))  # t: trial time
    return AlignedBatch(t, dtheta, dv, None if np.isnan(angles).any() else angles), cfg


def _concatenated(batches: list[AlignedBatch]) -> AlignedBatch:
    angles = None if any(b.angles is None for b in batches) else np.vstack([b.angles for b in batches])
    return AlignedBatch(np.concatenate([b.t for b in batches]), np.vstack([b.dtheta for b in batches]),
                        np.vstack([b.dv for b in batches]), angles, batches[0].t0)


def moving(batch: AlignedBatch, period: float) -> bool:
    """Whether the table moved: its angles span more than ``STATIC_ANGLE_SPAN``, or, without angles, the
    gyros' 1-s mean rates span more than ``STATIC_RATE_SPAN``."""
    if batch.angles is not None:
        return bool(np.max(np.ptp(np.unwrap(batch.angles, axis=0), axis=0)) > STATIC_ANGLE_SPAN)
    per_second = max(int(round(1.0 / period)), 1)
    n = len(batch) // per_second * per_second
    if n < 2 * per_second:
        return False
    means = batch.dtheta[:n].reshape(-1, per_second, 3).sum(axis=1)  # rad over each second: mean rate
    return bool(np.max(np.ptp(means, axis=0)) > STATIC_RATE_SPAN)


def run_noise(source: str | Path, out: Path, config: str | Path | None = None, level: float = DEFAULT_LEVEL,
              figure: bool = True, export: Path | None = None, rerun: bool = False) -> dict:
    """Analyse ``source`` and write OUT/noise.json, allan.png, report.html and (``rerun``) noise.rrd;
    returns the noise document."""
    from hil.outputs.noise import write_noise
    from hil.outputs.report import write_noise_report
    from hil.pipeline.table_motion import motion_residuals

    record = read_source(source, config)
    batch = record.batch
    if export is not None:
        write_increments_csv(export, batch)
    period = float(np.median(np.diff(batch.t))) if len(batch) > 1 else 0.0
    is_moving = moving(batch, period)
    dtheta, dv = batch.dtheta, batch.dv
    if is_moving:
        if batch.angles is None:
            raise TrialSetupError(f"{source}: the IMU moves and there are no table angles to take the motion out: "
                                  "the noise terms need a static trial, or the table's angles with the increments")
        cfg = record.cfg
        if cfg is None:
            raise TrialSetupError(f"{source}: a moving trial's CSV needs --config for the site and the table geometry")
        earth = Earth.from_degrees(cfg.site.latitude_deg, cfg.site.height_m)
        dtheta, dv = motion_residuals(batch, TableGeometry.from_config(cfg.turntable), earth)
    try:
        gyro, accel = analyse(dtheta, period, level), analyse(dv, period, level)
    except ValueError as exc:
        raise DataError(f"{source}: {exc}") from None
    extra = {"source": record.source, "samples": len(dtheta), "period_s": period,
             "motion_removed": is_moving}
    doc = write_noise(out, gyro, accel, figure=figure, extra=extra)
    write_noise_report(out)
    if rerun:
        from hil.viewer.allan_view import save_allan  # rerun only when asked for

        save_allan(out, doc)
    return doc
