"""``hil calibrate --simulate``: the calibration trial without transports or the emulator's process, as
fast as the CPU allows; deterministic for a ``trial.seed``.

The :class:`~hil.trial.calibration_sequence.CalibrationSequence` of the live trial commands a real servo in
this process (:class:`emulators.servo_simulation.ServoSimulation`) through the drivers' table client:
every command is formatted and parsed as on the wire, and a refusal raises as it does live. Simulated time
goes on in steps of ``Config.block_samples`` samples (0.05 s at 200 Hz by default), the blocks in which
the live processor hands samples and angles on: each step's samples, under the servo's plan so far (a
command acts at the first pulse after the step it was sent in), go through the
:class:`~hil.pipeline.processor.TrialProcessor` as one aligned batch, and the sequence, listening to it, takes
the block's samples and the table's reported angles, which advance it to send the next commands, as in the
live trial; over a calibration over temperature's soak, nothing but waiting, the blocks move the chamber and the
sensor's temperature on without making the samples (:func:`soak_unsampled`). The trial ends when the sequence
is done or fails, or at the emulated devices' bound on the schedule's length
(:func:`~hil.trial.calibration_outcome.emulated_length`), with the live trial's result; the table is sent Off on
every way out; then the same fit (:class:`~hil.trial.calibration_outcome.CalibrationOutcome`). Nothing is written
until the outcome's ``write``: a campaign's worker takes the result and the calibration document from the outcome.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from drivers.table_controller import InterlockError, LimitError, TableError
from emulators.chamber import SimulatedChamber, chamber_model
from emulators.servo_simulation import ServoSimulation
from hil.config import Config
from hil.estimation.calibration_schedule import Schedule
from hil.outputs.result import COMPLETED, TrialEnd
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.trial.calibration_feed import sequence_views
from hil.trial.calibration_outcome import CalibrationOutcome, checked_schedule, emulated_length
from hil.trial.calibration_sequence import CalibrationSequence
from hil.trial.calibration_settings import CalibrationSettings
from hil.trial.calibration_thermal import ThermalSequence
from hil.trial.outcome import TrialOutcome, TrialSetupError, emulated_truth
from hil.trial.viewer_feed import Viewer, ViewerFeed, ViewerOptions, open_viewer, watched_chamber


def run_calibration_simulation(cfg: Config, config_text: str, out: Path, options: ViewerOptions | None = None
                               ) -> tuple[CalibrationOutcome, Viewer | None]:
    """The simulated calibration trial (module docstring); its outcome (with the calibration when the
    schedule completed) and the viewer ``options`` ask for (none by default)."""
    settings = CalibrationSettings.of(cfg, simulated=True)
    schedule = checked_schedule(settings)
    sim = ServoSimulation.from_config(cfg)
    rate = settings.imu_rate_hz
    end = round(emulated_length(settings, schedule) * rate)  # samples
    step = cfg.block_samples
    viewer = open_viewer(dataclasses.replace(options or ViewerOptions(), layout="calibration"), cfg, out, blocking=True)
    client = sim.command_client(cfg.turntable)
    sequence = simulated_sequence(settings, schedule, sim, client, sequence_views(viewer, schedule, settings), viewer)
    processor = TrialProcessor(PipelineSettings.of(cfg),
                               listeners=[ViewerFeed(viewer, snapshots=False).on_progress, sequence.on_progress])
    try:
        client.apply_limits()
        sequence.start()
        client.sync_output(True)
        while not sequence.done and stopped(sequence) is None and sim.samples < end:
            if isinstance(sequence, ThermalSequence) and sequence.soaking:
                soak_unsampled(sim, sequence, processor, step, end)
            else:
                processor.feed_batch(sim.step(min(sim.samples + step, end) / rate))
    except (TableError, LimitError, InterlockError) as exc:
        if viewer is not None:
            viewer.close()
        raise TrialSetupError(str(exc)) from None
    finally:
        try:
            client.close()  # every axis Off, and the modes read back
        except TableError as exc:
            print(f"hil: WARNING: could not confirm the turntable is off: {exc}", file=sys.stderr)
    finished = processor.finish()
    sequence.report_rest()  # the last window, when the data ended at its end
    if viewer is not None and finished.estimator is not None:
        viewer.log_snapshots(finished.snapshots)
    ended = str(TrialEnd(COMPLETED) if stopped(sequence) is None else TrialEnd.early(stopped(sequence)))
    outcome = TrialOutcome.of(finished, cfg, config_text, out, ended, emulated_truth(cfg))
    unfinished = f"the schedule did not end within {end / rate:.0f} s of simulated time"
    return CalibrationOutcome.of_sequence(outcome, sequence, settings, unfinished), viewer


def simulated_sequence(settings: CalibrationSettings, schedule: Schedule, sim: ServoSimulation, client, views: dict,
                       viewer: Viewer | None):
    """The calibration's sequence on the simulated table ``client``: the schedule's, or at each of
    ``calibration.temperatures_c`` a soak and the schedule, the chamber then a first-order model in this process
    (:class:`emulators.chamber.SimulatedChamber`, of ``settings.chamber``) whose air the simulated IMU follows (its
    readings and set points to ``viewer`` too)."""
    period = settings.sample_period

    def sequence(steps: Schedule) -> CalibrationSequence:
        return CalibrationSequence(steps, client, period, **views)

    if settings.calibration.temperatures_c is None:
        return sequence(schedule)
    model = chamber_model(settings.chamber)
    sim.errors.follow_chamber(model.advance)
    chamber = watched_chamber(SimulatedChamber(model), None, viewer)
    return ThermalSequence(settings.calibration, schedule, client, chamber, sequence)


def soak_unsampled(sim: ServoSimulation, sequence: ThermalSequence, processor: TrialProcessor, step: int,
                   end: int) -> None:
    """The current soak to its end (or the trial's ``end``, samples) without the IMU's samples: in blocks of
    ``step`` samples as they would come, the soak judged at each block's last sample's time on the block's mean
    temperature, as the processor's progress gives them; the estimator then carries its attitude across the
    samples not made (the table held at the schedule's first position)."""
    start, rate = sim.samples / sim.rate_hz, sim.rate_hz
    while sequence.soaking and sim.samples < end:
        temperatures = sim.idle(min(sim.samples + step, end) / rate)
        mean = None if temperatures is None else float(temperatures.sum()) / len(temperatures)
        sequence.soak_update(sim.samples / rate, mean)
    processor.skip(sim.gap(start))


def stopped(sequence) -> str | None:
    """Why the sequence ends the trial early: a calibration over temperature's soak that failed, or a table that did
    not move as commanded; None while neither."""
    if isinstance(sequence, ThermalSequence) and sequence.soak_failure is not None:
        return sequence.soak_failure
    return None if sequence.failure is None else f"turntable is not moving as commanded: {sequence.failure}"
