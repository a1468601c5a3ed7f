"""``hil calibrate``: a live trial in which the harness commands the table through the calibration schedule
over ``acl`` (:mod:`hil.trial.calibration_sequence`), then fits the accelerometers and gyros on the
windows and writes ``calibration.json`` and ``calibration.html`` beside the trial's usual outputs.

The schedule is checked against ``turntable.limits`` before anything is started; the schedule sets the
trial's length (an emulated table gets twice its nominal length as a bound, and the trial ends when the
last window is complete). The table is turned off on every way out (:mod:`hil.trial.live_runner`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from hil.config import Config
from hil.outputs.result import COMPLETED
from hil.trial.outcome import TrialOutcome, TrialSetupError
from hil.trial.viewer_feed import ViewerOptions

QUEUE_ITEMS = 4  # keeps the emulated devices close behind the processing: commands act without lag
# The emulated devices run for this many times the schedule's nominal length (+ 120 s), and the trial ends when
# the schedule does. Each command acts as late as the data queued between the devices and the processing, so on
# a loaded machine the schedule takes longer in the devices' time than its nominal length (seen: beyond 2x + 60 s).
EMULATED_MARGIN = 4.0


def run_calibration(cfg: Config, config_path: Path, out: Path, speed: str, viewer: ViewerOptions,
                    quiet: bool = False, figures: bool = True) -> tuple[TrialOutcome, object]:
    """Run the schedule, calibrate, write the calibration outputs; returns the outcome (its result has a
    ``calibration`` block when the schedule completed) and the viewer."""
    from hil.estimation.calibration_schedule import (
        check_limits,
        schedule_duration,
        schedule_from_config,
    )
    from hil.frames import Earth, TableGeometry
    from hil.trial.calibration_feed import CalibrationFeed
    from hil.trial.calibration_sequence import CalibrationSequence
    from hil.trial.live_runner import emulated, run_live

    schedule = schedule_from_config(cfg.calibration)
    try:
        check_limits(schedule, cfg.turntable.limits)
    except ValueError as exc:
        raise TrialSetupError(f"{config_path}: {exc} (turntable.limits); nothing was sent") from None
    if not cfg.turntable.command_port:
        raise TrialSetupError("turntable.command_port: hil calibrate commands the table over acl; set its port "
                              "('emulator' for the emulated table)")
    is_emulated = emulated(cfg)
    nominal = schedule_duration(schedule, cfg.turntable.limits)
    duration = EMULATED_MARGIN * nominal + 120.0 if is_emulated else None
    sequences: list[CalibrationSequence] = []

    def commanded(control, cfg: Config, viewer) -> tuple[object, dict]:
        control.client.apply_limits()
        views = {}
        if viewer is not None:
            feed = CalibrationFeed(viewer, list(schedule.dwells) + list(schedule.plateaus),
                                   Earth.from_degrees(cfg.site.latitude_deg, cfg.site.height_m),
                                   TableGeometry.from_config(cfg.turntable))
            views = {"on_step": feed.on_step, "on_window": feed.on_window}
        sequence = CalibrationSequence(schedule, control.client, 1.0 / cfg.imu_rate_hz, **views)
        sequence.start()
        control.client.configure_sync(True)
        sequences.append(sequence)
        return sequence, {"on_samples": sequence.on_samples, "finished": lambda: sequence.done,
                          "queue_items": QUEUE_ITEMS}

    outcome, viewer = run_live(cfg, config_path, out, duration, speed, dataclasses.replace(viewer, layout="calibration"),
                               quiet, commanded)
    sequence = sequences[0] if sequences else None
    if outcome.ended == COMPLETED and (sequence is None or not sequence.done):
        where = sequence.progress if sequence is not None else "not started"
        outcome.result["ended"] = f"early: the devices stopped before the schedule ended ({where})"
    if outcome.ended == COMPLETED:
        outcome.result["calibration"] = _calibrate(cfg, sequence, out, figures and cfg.output.figures, is_emulated)
    return outcome, viewer


def _calibrate(cfg: Config, sequence, out: Path, figures: bool, is_emulated: bool) -> dict:
    """Fit the windows, write calibration.json and calibration.html; result.json's ``calibration`` block."""
    from hil.estimation.accel_calibration import calibrate_accelerometers
    from hil.estimation.gyro_calibration import calibrate_gyros
    from hil.frames import Earth, TableGeometry
    from hil.outputs.calibration import calibration_document, write_calibration
    from hil.outputs.calibration_report import (
        calibration_summary,
        observed_truth,
        window_residuals,
        write_calibration_report,
    )

    calibration = cfg.calibration
    windows = sequence.windows()
    earth = Earth.from_degrees(cfg.site.latitude_deg, cfg.site.height_m)
    geometry = TableGeometry.from_config(cfg.turntable)
    accel = calibrate_accelerometers(windows, earth, geometry, calibration.accel_terms, calibration.rank_tolerance)
    gyro = None
    if any(not w.static for w in windows):
        gyro = calibrate_gyros(windows, earth, geometry, accel.refined.theta[15:18],
                               accel.refined.covariance[15:18, 15:18], calibration.gyro_terms,
                               calibration.rank_tolerance)
    zero = cfg.turntable.zero_offset_arcsec
    truth = cfg.imu.errors if is_emulated else None
    doc = calibration_document(accel, gyro, windows, truth, zero if is_emulated else None)
    if truth is not None:
        doc["truth"]["as_observed"] = observed_truth(truth, zero)
    write_calibration(out / "calibration.json", doc)
    write_calibration_report(out, doc, window_residuals(windows, accel, gyro, earth, geometry), figures)
    return calibration_summary(doc)
