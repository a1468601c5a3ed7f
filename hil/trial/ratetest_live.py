"""The rate-table tests as live trials (``hil ratetest`` without ``--simulate``): the devices read from their
ports, or the emulated ones started in their own process, as ``hil calibrate`` does (:mod:`hil.trial.live_runner`):
the :class:`~hil.trial.rate_steps.RateSequence` listens to the pipeline and commands the table through the
trial's table control, and the trial ends when the last window is complete. The table is turned off on every
way out. An emulated trial runs for at most ``EMULATED_MARGIN`` times the steps' nominal length (+ 120 s).

The pipeline's gyro/table gate takes out samples whose gyro disagrees with the table by more than 1 % of the
rotation: at a constant rate it keeps every sample of a window and takes out a damaged frame, but a gyro whose
response lags a sinusoid it would take out wholesale, so the frequency response runs without it; and its IMU is
paired with the table by its counter and receive times alone, since a pairing by motion would take the gyro's lag
(rounded to whole samples) for the streams' offset, and the delay is what it measures (``response`` True:
``estimator.gyro_table_gate`` and ``estimator.pair_by_motion`` False). A frequency response whose streams were
paired anew at another offset on the way (a stall of the host that lost frames and wraps) ends early: its windows
on either side of it would disagree by the new pairing's error.
"""

from __future__ import annotations

from pathlib import Path

from drivers.controllers import make_controller
from hil.config import Config
from hil.outputs.result import COMPLETED, TrialEnd
from hil.trial.live import TrialHooks
from hil.trial.live_runner import run_live
from hil.trial.rig import emulated
from hil.trial.outcome import TrialSetupError
from hil.trial.rate_steps import RateSequence, RateStep
from hil.trial.viewer_feed import ViewerOptions

EMULATED_MARGIN = 4.0
QUEUE_ITEMS = 4  # the emulated devices close behind the processing: commands act without lag


def live_steps(cfg: Config, plan, config_path: Path, out: Path, speed: str, quiet: bool = False,
               response: bool = False):
    """Run the steps ``plan(gimbals)`` makes as a live trial (``response``: a frequency response's, module
    docstring); the windows and how it ended."""
    lagging = {"gyro_table_gate": not response, "pair_by_motion": not response, "flags_end_trial": False}
    cfg = cfg.model_copy(update={"estimator": cfg.estimator.model_copy(update=lagging)})
    if not cfg.turntable.command_port:
        raise TrialSetupError("turntable.command_port: hil ratetest commands the table; set its port "
                              "('emulator' for the emulated table)")
    steps: list[RateStep] = plan(tuple(make_controller(cfg.turntable, "").gimbals))  # refused before anything starts
    nominal = sum(s.window_s + s.settle_s + 5.0 for s in steps)
    duration = EMULATED_MARGIN * nominal + 120.0 if emulated(cfg) else None
    sequences: list[RateSequence] = []

    def commanded(control, viewer, chamber) -> TrialHooks:
        control.client.apply_limits()
        sequence = RateSequence(steps, control.client, 1.0 / cfg.imu_rate_hz)
        sequence.start()
        control.client.sync_output(True)
        sequences.append(sequence)
        return TrialHooks(motion_check=sequence, finished=lambda: sequence.done, queue_items=QUEUE_ITEMS)

    outcome, _ = run_live(cfg, config_path, out, duration, speed, ViewerOptions(), quiet, commanded)
    sequence = sequences[0] if sequences else None
    if outcome.ended != COMPLETED:
        return [], outcome.ended
    if sequence is None or not sequence.done:
        where = sequence.progress if sequence is not None else "not started"
        return [], str(TrialEnd.early(f"the devices stopped before the steps ended ({where})"))
    repaired = paired_anew(outcome.result["streams"]["sync"]) if response else None
    if repaired is not None:
        return [], str(TrialEnd.early(repaired))
    return sequence.windows(), COMPLETED


def paired_anew(sync: dict | None) -> str | None:
    """Why a frequency response's delay is not measured when its streams were paired anew at another offset
    (``streams.sync``'s first repair); None when they kept one pairing."""
    if not sync or not sync["repairs"]:
        return None
    first = sync["repairs"][0]
    return (f"the streams were paired anew at {first['at_s']:g} s ({first['cause']}): the frequency response's "
            "delay needs one pairing throughout; run it again")
