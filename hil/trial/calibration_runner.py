"""``hil calibrate``: a live trial in which the harness commands the table through the calibration schedule
through the controller interface (:mod:`hil.trial.calibration_sequence`), then fits the accelerometers and gyros on the
windows; the outcome writes ``calibration.json`` and ``calibration.html`` beside the trial's usual outputs
(:mod:`hil.trial.calibration_outcome`, shared with ``--simulate``, :mod:`hil.trial.calibration_simulation`).

The schedule is checked against ``turntable.limits`` before anything is started; the schedule sets the
trial's length (an emulated table gets :data:`~hil.trial.calibration_outcome.EMULATED_MARGIN` times its
nominal length as a bound, and the trial ends when the last window is complete). The table is turned off on
every way out (:mod:`hil.trial.live_runner`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from hil.config import Config
from hil.trial.calibration_feed import sequence_views
from hil.trial.calibration_outcome import CalibrationOutcome, checked_schedule, emulated_length
from hil.trial.calibration_sequence import CalibrationSequence
from hil.trial.calibration_thermal import ThermalSequence
from hil.trial.live import TrialHooks
from hil.trial.live_runner import emulated, run_live
from hil.trial.outcome import TrialSetupError
from hil.trial.viewer_feed import ViewerOptions

QUEUE_ITEMS = 4  # keeps the emulated devices close behind the processing: commands act without lag


def run_calibration(cfg: Config, config_path: Path, out: Path, speed: str, viewer: ViewerOptions,
                    quiet: bool = False) -> tuple[CalibrationOutcome, object]:
    """Run the schedule and calibrate; returns the outcome (with the calibration when the schedule
    completed; its :meth:`~CalibrationOutcome.write` writes the calibration outputs too) and the viewer."""
    schedule = checked_schedule(cfg, str(config_path))
    if not cfg.turntable.command_port:
        raise TrialSetupError("turntable.command_port: hil calibrate commands the table; set its port "
                              "('emulator' for the emulated table)")
    is_emulated = emulated(cfg)
    duration = emulated_length(cfg, schedule) if is_emulated else None
    sequences: list[CalibrationSequence] = []

    def commanded(control, cfg: Config, viewer, chamber) -> TrialHooks:
        control.client.apply_limits()
        limits = (cfg.limits.missing_max, cfg.limits.gated_max)  # a window may lack what the trial may
        lacking = 1.0 if limits == (None, None) else sum(v or 0.0 for v in limits)

        def schedule_sequence(steps) -> CalibrationSequence:
            return CalibrationSequence(steps, control.client, 1.0 / cfg.imu_rate_hz,
                                       **sequence_views(viewer, steps, cfg), lacking_max=lacking)

        thermal = cfg.calibration.temperatures_c is not None
        sequence = ThermalSequence(cfg, schedule, control.client, chamber, schedule_sequence) if thermal \
            else schedule_sequence(schedule)
        sequence.start()
        control.client.sync_output(True)
        sequences.append(sequence)
        return TrialHooks(motion_check=sequence, finished=lambda: sequence.done, queue_items=QUEUE_ITEMS,
                          early_end=(lambda: sequence.soak_failure) if thermal else lambda: None)

    outcome, viewer = run_live(cfg, config_path, out, duration, speed, dataclasses.replace(viewer, layout="calibration"),
                               quiet, commanded)
    for sequence in sequences:
        sequence.report_rest()  # the last window, when the data ended at its end, before the viewer closes
    return CalibrationOutcome.of_sequence(outcome, sequences[0] if sequences else None, is_emulated), viewer
