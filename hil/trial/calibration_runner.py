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
from hil.trial.calibration_settings import CalibrationSettings
from hil.trial.calibration_thermal import ThermalSequence
from hil.trial.live import TrialHooks
from hil.trial.live_runner import run_live
from hil.trial.rig import emulated
from hil.trial.outcome import TrialSetupError
from hil.trial.units import FixtureOutcome
from hil.trial.viewer_feed import ViewerOptions

QUEUE_ITEMS = 4  # keeps the emulated devices close behind the processing: commands act without lag


def run_calibration(cfg: Config, config_path: Path, out: Path, speed: str, viewer: ViewerOptions,
                    quiet: bool = False) -> tuple[CalibrationOutcome, object]:
    """Run the schedule and calibrate; returns the outcome (with the calibration when the schedule
    completed; its :meth:`~CalibrationOutcome.write` writes the calibration outputs too) and the viewer."""
    settings = CalibrationSettings.of(cfg)
    schedule = checked_schedule(settings, str(config_path))
    if not cfg.turntable.command_port:
        raise TrialSetupError("turntable.command_port: hil calibrate commands the table; set its port "
                              "('emulator' for the emulated table)")
    is_emulated = emulated(cfg)
    duration = emulated_length(settings, schedule) if is_emulated else None
    sequences: list[CalibrationSequence] = []

    def commanded(control, viewer, chamber) -> TrialHooks:
        control.client.apply_limits()

        def schedule_sequence(steps) -> CalibrationSequence:
            return CalibrationSequence(steps, control.client, settings.sample_period,
                                       **sequence_views(viewer, steps, settings), lacking_max=settings.lacking_max)

        thermal = settings.calibration.temperatures_c is not None
        sequence = ThermalSequence(settings.calibration, schedule, control.client, chamber, schedule_sequence) \
            if thermal else schedule_sequence(schedule)
        sequence.start()
        control.client.sync_output(True)
        sequences.append(sequence)
        return TrialHooks(motion_check=sequence, finished=lambda: sequence.done, queue_items=QUEUE_ITEMS,
                          early_end=(lambda: sequence.soak_failure) if thermal else lambda: None)

    outcome, viewer = run_live(cfg, config_path, out, duration, speed, dataclasses.replace(viewer, layout="calibration"),
                               quiet, commanded)
    for sequence in sequences:
        sequence.report_rest()  # the last window, when the data ended at its end, before the viewer closes
    return CalibrationOutcome.of_sequence(outcome, sequences[0] if sequences else None, settings), viewer


def run_units_calibration(cfg: Config, config_path: Path, out: Path, speed: str, quiet: bool = False
                          ) -> FixtureOutcome:
    """The schedule run once for every unit on the table (docs/units.md): the first unit's sequence commands it,
    each other unit's follows the reported angles by the same rules and cuts its own windows; each unit calibrated
    on its own windows, through its own mounting."""
    from hil.trial.units_live import UnitsCommand, run_units_live

    shared = CalibrationSettings.of(cfg)  # the units' calibration block and table, the units' own read below
    schedule = checked_schedule(shared, str(config_path))
    if not cfg.turntable.command_port:
        raise TrialSetupError("turntable.command_port: hil calibrate commands the table; set its port "
                              "('emulator' for the emulated table)")
    if shared.calibration.temperatures_c is not None:
        raise TrialSetupError("calibration.temperatures_c: a calibration over temperature takes one unit so far")
    is_emulated = emulated(cfg)
    units: dict[str, CalibrationSettings] = {}  # each unit's own, read from its config as its trial is made
    sequences: dict[str, CalibrationSequence] = {}

    def unit(name: str, client, unit_cfg: Config) -> TrialHooks:
        settings = units[name] = CalibrationSettings.of(unit_cfg)
        sequence = sequences[name] = CalibrationSequence(schedule, client, settings.sample_period,
                                                         lacking_max=settings.lacking_max)
        sequence.start()
        return TrialHooks(motion_check=sequence, finished=lambda: sequence.done, queue_items=QUEUE_ITEMS)

    command = UnitsCommand(arm=lambda control: control.client.apply_limits(), unit=unit,
                           started=lambda control: control.client.sync_output(True))
    fixture = run_units_live(cfg, config_path, out, emulated_length(shared, schedule) if is_emulated else None,
                             speed, quiet, command)
    for sequence in sequences.values():
        sequence.report_rest()
    return FixtureOutcome(fixture.name, out, {name: CalibrationOutcome.of_sequence(outcome, sequences.get(name),
                                                                                   units[name])
                                              for name, outcome in fixture.units.items()},
                          absent=fixture.absent)
