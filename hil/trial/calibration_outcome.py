"""What the two calibration runners share (the live trial, :mod:`hil.trial.calibration_runner`, and the
simulated one, :mod:`hil.trial.calibration_simulation`): the schedule checked against the table's limits,
the emulated table's bound on its length, the fit of the windows, and the outcome that carries the
calibration document and writes ``calibration.json`` and ``calibration.html`` beside the trial's outputs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.table_controller import TableError
from hil.estimation.accel_calibration import calibrate_accelerometers
from hil.estimation.calibration_model import Window
from hil.estimation.calibration_schedule import Schedule, check_limits, schedule_duration, schedule_from_config
from hil.estimation.gyro_calibration import calibrate_gyros
from hil.outputs.calibration import calibration_document, write_calibration
from hil.outputs.calibration_thermal import thermal_document, thermal_section
from hil.outputs.calibration_report import (
    Residuals,
    calibration_summary,
    observed_truth,
    window_residuals,
    write_calibration_report,
    write_residual_figure,
)
from hil.outputs.figures import Draw, write_figures
from hil.outputs.judgement import Judgement
from hil.outputs.result import COMPLETED, TrialEnd
from hil.samples import GIMBAL_AXES
from hil.trial.calibration_settings import CalibrationSettings
from hil.trial.calibration_thermal import ThermalSequence
from hil.trial.outcome import TrialOutcome, TrialSetupError
from hil.trial.table_control import check_controller
from hil.vocabulary import TrialKind

# The emulated devices run for this many times the schedule's nominal length (+ 120 s), and the trial ends when
# the schedule does. Each command acts as late as the data queued between the devices and the processing, so on
# a loaded machine the schedule takes longer in the devices' time than its nominal length (seen: beyond 2x + 60 s).
EMULATED_MARGIN = 4.0
UNFINISHED = "the devices stopped before the schedule ended"


def checked_schedule(settings: CalibrationSettings, where: str | None = None) -> Schedule:
    """``calibration``'s schedule; raises :class:`TrialSetupError` (prefixed with ``where``) when a step lies
    outside ``turntable.limits`` or needs what ``turntable.controller`` cannot do."""
    schedule = schedule_from_config(settings.calibration)
    prefix = f"{where}: " if where else ""
    try:
        check_limits(schedule, settings.turntable.limits)
    except ValueError as exc:
        raise TrialSetupError(f"{prefix}{exc} (turntable.limits); nothing was sent") from None
    steps = list(schedule.dwells) + list(schedule.plateaus)
    gimbals = {g for k, g in enumerate(GIMBAL_AXES) if any(s.angles[k] for s in steps)}
    gimbals |= {GIMBAL_AXES[p.axis] for p in schedule.plateaus}
    try:
        check_controller(settings.turntable, {"position"} | ({"rate"} if schedule.plateaus else set()), gimbals)
    except TableError as exc:
        raise TrialSetupError(f"{prefix}{exc}") from None
    return schedule


def emulated_length(settings: CalibrationSettings, schedule: Schedule) -> float:
    """Trial seconds the emulated devices run for a schedule (see :data:`EMULATED_MARGIN`), at each of
    ``calibration.temperatures_c`` after a soak of at most ``calibration.soak.timeout_s``."""
    length = EMULATED_MARGIN * schedule_duration(schedule, settings.turntable.limits) + 120.0
    temperatures = settings.calibration.temperatures_c
    return length if temperatures is None else len(temperatures) * (length + settings.calibration.soak.timeout_s)


@dataclass
class CalibrationOutcome(TrialOutcome):
    """A calibration trial's outcome: :attr:`calibration` is calibration.json's document (the terms, their
    sigmas, the windows and, for an emulated IMU, the truth), None when the schedule did not complete;
    :attr:`residuals` are its windows' residuals, for calibration.html. result.json's ``calibration`` block
    is its summary."""

    calibration: dict | None = None
    residuals: Residuals | None = None

    def filed_as(self) -> tuple[str, dict, Path | None]:
        return TrialKind.CALIBRATION, self.calibration or {}, None

    @classmethod
    def of_sequence(cls, outcome: TrialOutcome, sequence, settings: CalibrationSettings,
                    unfinished: str = UNFINISHED) -> CalibrationOutcome:
        """``outcome`` with the calibration of the windows of ``sequence`` (a
        :class:`~hil.trial.calibration_sequence.CalibrationSequence`, or None when it never started) when
        the trial and the schedule completed, fitted with its trial's ``settings``; a completed trial whose
        schedule did not is ended early, ``unfinished`` saying why."""
        fields = {f.name: getattr(outcome, f.name) for f in dataclasses.fields(TrialOutcome)}
        if outcome.ended == COMPLETED and (sequence is None or not sequence.done):
            where = sequence.progress if sequence is not None else "not started"
            fields["result"]["ended"] = str(TrialEnd.early(f"{unfinished} ({where})"))
        if fields["result"]["ended"] != COMPLETED:
            return cls(**fields)

        try:
            document, residuals = fit_sequence(settings, sequence)
        except ValueError as exc:  # a window whose samples were all lost (gated out, or gaps in the data)
            fields["result"]["ended"] = str(TrialEnd.early(exc))
            return cls(**fields)
        fields["result"]["calibration"] = calibration_summary(document)
        return cls(**fields, calibration=document, residuals=residuals)

    def write(self, figures: bool = True, draw: Draw = write_figures) -> Judgement:
        """The residual figure (when calibrated), the trial's outputs, then calibration.json with the trial's
        record and calibration.html headed by its verdict; returns the trial's judgement."""
        image = None
        if self.calibration is not None and self.calibration["positions"] and figures and self.settings.figures:
            image = write_residual_figure(self.out, self.residuals)  # before the report, which leads with it
        judged = super().write(figures, draw)
        if self.calibration is not None:
            if "record" in self.result:
                self.calibration["record"] = self.result["record"]
            write_calibration(self.out / "calibration.json", self.calibration)
            thermal = "thermal" in self.calibration
            extra = thermal_section(self.calibration, figures and self.settings.figures) if thermal else ""
            write_calibration_report(self.out, self.calibration, self.result, judged.verdict, image, extra)
        return judged


def fit_sequence(settings: CalibrationSettings, sequence) -> tuple[dict, Residuals]:
    """The calibration of a completed sequence's windows: at one temperature (:func:`fit_windows`), or at each
    of a :class:`~hil.trial.calibration_thermal.ThermalSequence`'s with the terms' polynomials over them
    (:func:`~hil.outputs.calibration_thermal.thermal_document`, the residuals of every temperature in turn).
    ValueError for a window that lost its samples."""
    if not isinstance(sequence, ThermalSequence):
        return fit_windows(settings, sequence.windows())
    fits = [fit_windows(settings, point.sequence.windows()) for point in sequence.points]
    document = thermal_document(settings.calibration.thermal_order, [point.record() for point in sequence.points],
                                [doc for doc, _ in fits], settings.truth, settings.turntable.zero_offset_arcsec)
    parts = [residuals for _, residuals in fits]
    joined = [None if getattr(parts[0], f.name) is None else np.vstack([getattr(r, f.name) for r in parts])
              for f in dataclasses.fields(Residuals)]
    return document, Residuals(*joined)


def fit_windows(settings: CalibrationSettings, windows: list[Window]) -> tuple[dict, Residuals]:
    """Fit the accelerometers on the dwells and the gyros on every window (when there are plateaus);
    calibration.json's document (with ``truth`` and ``truth.as_observed`` when ``settings`` carry the IMU's
    errors) and the residuals."""
    calibration, earth, geometry = settings.calibration, settings.earth, settings.geometry
    accel = calibrate_accelerometers(windows, earth, geometry, calibration.accel_terms, calibration.rank_tolerance)
    gyro = None
    if any(not w.static for w in windows):
        gyro = calibrate_gyros(windows, earth, geometry, accel.refined.theta[15:18],
                               accel.refined.covariance[15:18, 15:18], calibration.gyro_terms,
                               calibration.rank_tolerance)
    zero, errors = settings.turntable.zero_offset_arcsec, settings.truth
    document = calibration_document(accel, gyro, windows, errors, None if errors is None else zero)
    if errors is not None:
        document["truth"]["as_observed"] = observed_truth(errors, zero, geometry.body_to_mount_matrix)
    return document, window_residuals(windows, accel, gyro, earth, geometry)
