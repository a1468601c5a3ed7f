"""``hil noise``: the Allan deviation and the IEEE noise terms of a trial's increments.

The source is a trial config (its devices read, or simulated as ``hil simulate``), a run directory or
recording (replayed through the same decoding, alignment and gates as the live run) or a CSV of increments. A static trial
is analysed as it is (earth rate and gravity are constants, invisible to the Allan variance); on a
moving one the table's motion is first taken out with its angles (:mod:`hil.pipeline.table_motion`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulators.simulation import Simulation
from hil.config import Config, ImuErrors, RecordConfig, load_config
from hil.estimation.allan import DEFAULT_LEVEL, AllanAnalysis, analyse
from hil.estimation.allan_detrend import TEMPERATURE_DEGREE, linear_trend, temperature_trend
from hil.estimation.allan_fit import TERM_NAMES
from hil.estimation.allan_taus import parse_taus
from hil.frames import Earth, TableGeometry
from hil.inputs import resolve_path
from hil.outputs.noise import SENSORS, noise_document, write_noise
from hil.outputs.trial_report import write_noise_report
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.pipeline.table_motion import motion_residuals
from hil.recording.csv_input import DataError, read_increments_csv, write_increments_csv
from hil.recording.replay import open_recording, recorded_pace
from hil.samples import AlignedBatch
from hil.trial.noise_acquisition import acquire
from hil.trial.outcome import TrialSetupError
from hil.units import DEG, DEG_PER_H, HOUR, SQRT_HOUR, UG

STATIC_ANGLE_SPAN = 1e-3 * DEG  # table angles spanning less than this: a static trial
STATIC_RATE_SPAN = 0.5 * DEG  # rad/s: 1-s mean rates spanning more than this without angles: a moving IMU
FORMING_HALVINGS = 8  # a live view is shown the analysis of the record's first T / 2^k, k = this .. 1, then T's


@dataclass(frozen=True)
class NoiseSource:
    """What ``hil noise`` reads: ``source`` a run directory or recording, a CSV (``config``: its site and table,
    needed when it moves) or a trial config; ``duration`` s to simulate or acquire (None: ``trial.duration_s``);
    ``quiet``: no progress line while acquiring."""

    source: str | Path
    config: str | Path | None = None
    duration: float | None = None
    quiet: bool = False


@dataclass(frozen=True)
class AllanSettings:
    """How a record is analysed: the two-sided ``level`` of every interval, the tau grid ``taus`` (``octave``,
    ``decade``, ``all`` or taus in s: :func:`~hil.estimation.allan_taus.parse_taus`) and the ``detrend``
    (``none``, ``linear`` or ``temperature``, see :func:`analyse_record`)."""

    level: float = DEFAULT_LEVEL
    taus: str | tuple[float, ...] = "octave"
    detrend: str = "none"


@dataclass(frozen=True)
class NoiseSettings:
    """What the analysis takes from a trial's config, read once by :meth:`NoiseSettings.of`: the trial's name, the
    site and the table's geometry (a moving record's motion taken out) and the ``record`` block."""

    trial_name: str
    earth: Earth
    geometry: TableGeometry
    record: RecordConfig

    @classmethod
    def of(cls, cfg: Config) -> NoiseSettings:
        """The settings of a one-unit :class:`hil.config.Config`."""
        return cls(cfg.trial.name, Earth.from_config(cfg.site),
                   TableGeometry.from_config(cfg.turntable), cfg.record)


@dataclass(frozen=True)
class NoiseRecord:
    """A trial's increments and what the analysis needs to know of the trial."""

    batch: AlignedBatch
    source: str  # "devices", "simulation", "recording" or "csv"
    settings: NoiseSettings | None  # the trial's (site, table): --config's, else the recorded or simulated config's

    @property
    def source_record(self) -> RecordConfig | None:
        """The ``record`` block of the config the source was (simulated or acquired from its devices); None for a
        recording or a CSV."""
        if self.settings is None or self.source not in ("simulation", "devices"):
            return None
        return self.settings.record


def read_source(source: NoiseSource, out: Path) -> NoiseRecord:
    """The increments of ``source``: a run directory or recording, a CSV, or a config: simulated, or, when its
    devices are read from ports, acquired from them into ``out`` (:mod:`hil.trial.noise_acquisition`)."""
    path, duration = Path(source.source), source.duration
    given = None if source.config is None else load_config(source.config)
    if path.is_dir() or path.suffix == ".mcap":
        batch, recorded = _replayed(path)
        return NoiseRecord(batch, "recording", NoiseSettings.of(given or recorded))
    if path.suffix == ".csv":
        return NoiseRecord(read_increments_csv(path, given), "csv", None if given is None else NoiseSettings.of(given))
    cfg = load_config(resolve_path(path))
    if cfg.imu.source == cfg.turntable.source == "emulator":
        if duration is not None:  # --duration: the simulated trial's length too
            cfg = cfg.model_copy(update={"trial": cfg.trial.model_copy(update={"duration_s": duration})})
        return simulated(cfg)

    return NoiseRecord(_replayed(acquire(cfg, path, out, duration, source.quiet))[0], "devices",
                       NoiseSettings.of(cfg))


def simulated(cfg: Config) -> NoiseRecord:
    """The emulator's increments of a trial config, as ``hil simulate`` draws them."""
    return NoiseRecord(_concatenated(list(Simulation.from_config(cfg).batches())), "simulation",
                       NoiseSettings.of(cfg))


def _replayed(path: Path) -> tuple[AlignedBatch, Config]:
    """The samples the estimator took in a replay of the recording, and the recorded config."""
    recording, cfg = open_recording(path)
    runs: list[AlignedBatch] = []
    time_scale = recorded_pace(recording)[1]
    processor = TrialProcessor(PipelineSettings.of(cfg), None, time_scale,
                               [lambda progress: runs.extend(progress.samples())])
    with recording:
        for item in recording:
            processor.feed(item)
    processor.finish()
    if not runs:
        raise DataError(f"{path}: no IMU sample reached the estimator: nothing to analyse")
    t, dtheta, dv, angles = (np.concatenate([getattr(run, name) for run in runs])  # t: trial time
                             for name in ("t", "dtheta", "dv", "angles"))
    return AlignedBatch(t, dtheta, dv, None if np.isnan(angles).any() else angles), cfg


def _concatenated(batches: list[AlignedBatch]) -> AlignedBatch:
    angles = None if any(b.angles is None for b in batches) else np.vstack([b.angles for b in batches])
    temperature = (None if any(b.temperature_c is None for b in batches)
                   else np.concatenate([b.temperature_c for b in batches]))
    return AlignedBatch(np.concatenate([b.t for b in batches]), np.vstack([b.dtheta for b in batches]),
                        np.vstack([b.dv for b in batches]), angles, batches[0].t0, temperature_c=temperature)


def noise_truth(errors: ImuErrors, rate_hz: float) -> dict:
    """The noise terms the emulator's error model (:mod:`emulators.sensor_errors`) gives a static trial, in
    noise.json's keys and units: an output quantised to q with its remainder carried errs in its angle
    (velocity) by a white sequence of variance q^2 / 12, so Q = q / sqrt(12) (IEEE 952 Eq. C.8; white while the
    angle moves by q or more a sample); white rate noise of 1-sigma s per sample of period T = 1 / rate has
    the Allan variance s^2 T / tau (the mean of m = tau / T independent samples), so N = s sqrt(T); the bias
    instability B, the rate random walk K and the linear drift, the rate ramp R, are configured as the IEEE 952
    coefficients themselves (Eqs. C.15, C.17, C.20)."""
    period = 1.0 / rate_hz
    e = errors
    rates = {"gyro": (e.dtheta_quantum_rad, np.array(e.gyro_noise_dph) * DEG_PER_H,
                      np.array(e.gyro_bias_instability_dph) * DEG_PER_H,
                      np.array(e.gyro_random_walk_dph_per_sqrt_h) * DEG_PER_H / SQRT_HOUR,
                      np.array(e.gyro_drift_dph_per_h) * DEG_PER_H / HOUR),
             "accel": (e.dv_quantum_mps, np.array(e.accel_noise_ug) * UG, np.array(e.accel_bias_instability_ug) * UG,
                       np.array(e.accel_random_walk_ug_per_sqrt_h) * UG / SQRT_HOUR,
                       np.array(e.accel_drift_ug_per_h) * UG / HOUR)}
    truth = {}
    for sensor, units, keys in SENSORS:
        quantum, white, instability, walk, ramp = rates[sensor]
        si = (np.full(3, quantum / math.sqrt(12.0)), white * math.sqrt(period), instability, walk, np.abs(ramp))
        scale = [getattr(units, name) for name in TERM_NAMES]
        truth[sensor] = {key: [float(v) for v in value / unit] for key, value, unit in zip(keys, si, scale)}
    return truth


def moving(batch: AlignedBatch, period: float) -> bool:
    """Whether the table moved: its angles span more than ``STATIC_ANGLE_SPAN``, or, without angles, the
    gyros' 1-s mean rates span more than ``STATIC_RATE_SPAN``."""
    if batch.angles is not None:
        return bool(np.max(np.ptp(np.unwrap(batch.angles, axis=0), axis=0)) > STATIC_ANGLE_SPAN)
    per_second = max(round(1.0 / period), 1)
    n = len(batch) // per_second * per_second
    if n < 2 * per_second:
        return False
    means = batch.dtheta[:n].reshape(-1, per_second, 3).sum(axis=1)  # rad over each second: mean rate
    return bool(np.max(np.ptp(means, axis=0)) > STATIC_RATE_SPAN)


@dataclass(frozen=True)
class NoiseAnalysis:
    """The Allan analyses of a record's gyros and accelerometers and their noise.json document."""

    gyro: AllanAnalysis
    accel: AllanAnalysis
    doc: dict


def with_gaps(t: np.ndarray, period: float, *columns: np.ndarray) -> tuple[int, list[np.ndarray]]:
    """The samples missing between the times t (a step of k periods, rounded, leaves k - 1 out) and the
    columns with a NaN row in each missing sample's place."""
    steps = np.maximum(np.rint(np.diff(t) / period).astype(int), 1) if len(t) > 1 else np.zeros(0, dtype=int)
    index = np.concatenate([[0], np.cumsum(steps)])
    missing = int(index[-1] + 1 - len(t))
    if not missing:
        return 0, list(columns)
    filled = []
    for column in columns:
        full = np.full((index[-1] + 1,) + column.shape[1:], np.nan)
        full[index] = column
        filled.append(full)
    return missing, filled


def analyse_record(record: NoiseRecord, label: str, settings: AllanSettings = AllanSettings()) -> NoiseAnalysis:
    """The Allan deviation on the settings' tau grid and the noise terms of a record (the table's motion taken out
    first if it moved; samples missing in gaps left out, ``missing`` in the document; with the ``detrend``
    ``linear`` each rate's linear trend, the ramp, removed, with ``temperature`` the part a polynomial of the
    IMU's reported temperature explains, ``detrend`` in the document); ``label`` names the source in errors.
    Nothing is written."""
    level, taus, detrend = settings.level, settings.taus, settings.detrend
    batch = record.batch
    period = float(np.median(np.diff(batch.t))) if len(batch) > 1 else 0.0
    is_moving = moving(batch, period)
    dtheta, dv = batch.dtheta, batch.dv
    if is_moving:
        if batch.angles is None:
            raise TrialSetupError(f"{label}: the IMU moves and there are no table angles to take the motion out: "
                                  "the noise terms need a static trial, or the table's angles with the increments")
        trial = record.settings
        if trial is None:
            raise TrialSetupError(f"{label}: a moving trial's CSV needs --config for the site and the table geometry")
        dtheta, dv = motion_residuals(batch, trial.geometry, trial.earth)
    temperature = np.full(len(batch), np.nan) if batch.temperature_c is None else batch.temperature_c
    missing, (dtheta, dv, temperature) = with_gaps(batch.t, period, dtheta, dv, temperature)
    removed, taken = (), {"kind": detrend}
    if detrend == "linear":
        (dtheta, gyro_slope), (dv, accel_slope) = linear_trend(dtheta, period), linear_trend(dv, period)
        removed = ("ramp",)
        taken.update({sensor: {keys[TERM_NAMES.index("ramp")]: [float(v) for v in slope / units.ramp]}
                      for (sensor, units, keys), slope in zip(SENSORS, (gyro_slope, accel_slope))})
    elif detrend == "temperature":
        if not np.isfinite(temperature).any():
            raise DataError(f"{label}: --detrend temperature: the record carries no IMU temperature")
        (dtheta, gyro_fit), (dv, accel_fit) = (temperature_trend(x, period, temperature) for x in (dtheta, dv))
        taken.update(_temperature_coefficients(gyro_fit, accel_fit, float(np.nanmean(temperature))))
    try:
        gyro, accel = analyse(dtheta, period, level, taus, removed), analyse(dv, period, level, taus, removed)
    except ValueError as exc:
        raise DataError(f"{label}: {exc}") from None
    extra = {"source": record.source, "samples": len(batch), "period_s": period, "motion_removed": is_moving,
             "missing": missing, "detrend": taken}
    return NoiseAnalysis(gyro, accel, {**noise_document(gyro, accel), **extra})


def _temperature_coefficients(gyro: np.ndarray, accel: np.ndarray, about_c: float) -> dict:
    """noise.json's account of a temperature detrend: the polynomial's coefficients (degree, 3) per sensor in
    deg/h and ug per deg C^j, about the mean temperature."""
    units = {"gyro": (DEG_PER_H, "bias_dph_per_c"), "accel": (UG, "bias_ug_per_c")}
    out: dict = {"about_c": about_c, "degree": TEMPERATURE_DEGREE}
    for sensor, fit in (("gyro", gyro), ("accel", accel)):
        unit, key = units[sensor]
        out[sensor] = {key + ("" if j == 1 else str(j)): [float(v) for v in row / unit]
                       for j, row in enumerate(fit, start=1)}
    return out


def run_noise(source: NoiseSource, out: Path, settings: AllanSettings = AllanSettings(), *, figure: bool = True,
              export: Path | None = None, view=None, record: Callable[[RecordConfig | None], dict] | None = None
              ) -> dict:
    """Analyse ``source`` with ``settings`` (its ``taus`` as ``--taus`` gives them, comma separated) and write
    OUT/noise.json, allan.png and report.html; returns the noise document. ``view`` (an
    :class:`~hil.viewer.allan_view.AllanView`, or None) is shown the curves as they form (:func:`show_forming`).
    A config that reads devices is acquired first (see :mod:`hil.trial.noise_acquisition`).
    ``record(block)`` gives noise.json's ``record`` once the analysis is done (``block``:
    :attr:`NoiseRecord.source_record`)."""
    try:
        settings = dataclasses.replace(settings, taus=parse_taus(settings.taus))
    except ValueError as exc:
        raise DataError(str(exc)) from None
    samples = read_source(source, out)
    if export is not None:
        write_increments_csv(export, samples.batch)
    label = str(source.source)
    analysis = analyse_record(samples, label, settings)
    analysis.doc["trial"] = {"name": samples.settings.trial_name if samples.settings else Path(source.source).stem}
    if record is not None:
        analysis.doc["record"] = record(samples.source_record)
    if view is not None:
        show_forming(view, samples, analysis, lambda part: analyse_record(part, label, settings))
    write_noise(out, analysis.doc, analysis.gyro, analysis.accel, figure=figure)
    write_noise_report(out)
    return analysis.doc


def show_forming(view, record: NoiseRecord, whole: NoiseAnalysis,
                 analysed: Callable[[NoiseRecord], NoiseAnalysis]) -> None:
    """Show ``view`` the analysis of the record's first ``T / 2^k`` (``k`` from ``FORMING_HALVINGS`` down to 1;
    the parts too short for an analysis left out), each at its record time, then the ``whole`` record's: the long
    taus join as the record doubles, the short ones settle. The parts cost about one more analysis of the whole."""
    batch = record.batch
    total = float(batch.t[-1] - batch.t0)
    for k in range(FORMING_HALVINGS, 0, -1):
        n = len(batch) >> k
        if n < 2:
            continue
        part = dataclasses.replace(record, batch=_first(batch, n))
        try:
            doc = analysed(part).doc
        except (DataError, TrialSetupError):  # too short for four octaves of tau, or for the motion's removal
            continue
        view.show(float(batch.t[n - 1] - batch.t0), total, doc)
    view.show(total, total, whole.doc)


def _first(batch: AlignedBatch, n: int) -> AlignedBatch:
    """The batch's first ``n`` samples."""
    cut = {name: None if getattr(batch, name) is None else getattr(batch, name)[:n]
           for name in ("t", "dtheta", "dv", "angles", "valid", "temperature_c")}
    return dataclasses.replace(batch, **cut)
