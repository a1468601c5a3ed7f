"""What every trial runner returns, and how it becomes the trial's outputs."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hil.config import Config, InputError, ReportLimits
from hil.estimation.online import Snapshot
from hil.outputs.figures import Draw, write_figures
from hil.outputs.judgement import Judgement
from hil.outputs.record import RecordSource
from hil.outputs.result import (COMPLETED, TrialEnd, non_finite_figure, summary_text, trial_result,
                               verdict_exit_code)
from hil.outputs.trial_outputs import write_trial_outputs
from hil.pipeline.compensation import compensated_bias, load_calibration
from hil.pipeline.progress import Finished
from hil.units import UG
from hil.vocabulary import TrialKind


class TrialSetupError(InputError, ValueError):
    """A trial that cannot start as asked (arguments, ports, viewer, table); the message says why."""


def emulated_truth(cfg: Config) -> dict | None:
    """result.json's ``truth``: the accelerometer bias (µg) and its drift (µg/h) of the output the estimator sees,
    for comparison in the outputs; None for real devices. That is what the emulator injects, through the
    ``imu.calibration`` applied to it when one is (:func:`hil.pipeline.compensation.compensated_bias`)."""
    if cfg.imu.source != "emulator":
        return None
    errors = cfg.imu.errors
    if not cfg.imu.calibration:
        return {"accel_bias_ug": list(errors.accel_bias_ug), "accel_drift_ug_per_h": list(errors.accel_drift_ug_per_h)}
    accel, _ = load_calibration(cfg.imu.calibration)
    bias, drift = compensated_bias(accel, np.array(errors.accel_bias_ug) * UG,
                                   np.array(errors.accel_drift_ug_per_h) * UG)
    return {"accel_bias_ug": [float(b) for b in bias / UG], "accel_drift_ug_per_h": [float(d) for d in drift / UG]}


@dataclass(frozen=True)
class OutputSettings:
    """What a finished trial's outputs take from its config, read once by :meth:`of`: ``output.limits``, whether
    ``output.figures`` are drawn, and the source of its record."""

    limits: ReportLimits
    figures: bool
    record: RecordSource

    @classmethod
    def of(cls, cfg: Config) -> OutputSettings:
        """The output settings of a one-unit config."""
        return cls(cfg.limits, cfg.output.figures, RecordSource.of(cfg))


@dataclass
class TrialOutcome:
    """A finished trial: its output settings, config text and output directory, the result.json document, the
    snapshots and the IMU's temperature at each (by its time)."""

    settings: OutputSettings
    config_text: str
    out: Path
    result: dict
    snapshots: list[Snapshot]
    temperatures: Mapping[float, float] = field(default_factory=dict)

    @property
    def ended(self) -> str:
        return self.result["ended"]

    @classmethod
    def of(cls, finished: Finished, cfg: Config, config_text: str, out: Path, ended: str = COMPLETED,
           truth: dict | None = None) -> TrialOutcome:
        """The outcome of a pipeline's end; ``ended`` says how the trial ended, ``calibration_applied``
        which ``imu.calibration`` file and terms the pipeline applied (null: none). A trial that ran its course to
        an estimate holding NaN or infinity ended early: it has no figure to judge."""
        result = trial_result(cfg.trial.name, finished.estimator, finished.streams, truth, cfg.estimator.bias_model)
        figure = non_finite_figure(result) if ended == COMPLETED else None
        if figure is not None:
            ended = str(TrialEnd.early(f"{figure} is not finite: the data holds values the estimator cannot take"))
        result = {"trial": result["trial"], "ended": ended, "calibration_applied": finished.calibration_applied,
                  **{k: v for k, v in result.items() if k != "trial"}}
        return cls(OutputSettings.of(cfg), config_text, out, result, finished.snapshots, finished.temperatures)

    def filed_as(self) -> tuple[str, dict, Path | None]:
        """How the history files this trial (docs/history.md): its kind, the document its figures are read from,
        and the run directory of the trial it re-processed (a replay's; else None)."""
        return TrialKind.SWING, self.result, None

    def exit_code(self, verdict: str) -> int:
        """The exit code (docs/contracts.md, "Exit codes"): 1 a trial that ended early or was interrupted, 3 one that
        completed but FAILs its limits, 0 otherwise."""
        return verdict_exit_code(verdict)

    def write(self, figures: bool = True, draw: Draw = write_figures) -> Judgement:
        """Write every output and print the summary (the figures drawn by ``draw``); returns the trial's judgement:
        its measurements and its verdict, PASS or FAIL against ``output.limits`` for a completed trial, else
        INTERRUPTED or ENDED EARLY."""
        judged = write_trial_outputs(self.out, self.result, self.snapshots, self.settings.limits,
                                     self.config_text, figures=figures and self.settings.figures, draw=draw,
                                     temperatures=self.temperatures)
        print(summary_text(self.result, self.out))
        against = "against output.limits" if self.ended == COMPLETED else \
            "(did not complete: not judged against output.limits)"
        print(f"  report: {judged.verdict} {against} ({self.out / 'report.html'})")
        return judged
