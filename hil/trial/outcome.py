"""What every trial runner returns, and how it becomes the trial's outputs."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from hil.config import Config
from hil.estimation.online import Snapshot
from hil.outputs.result import COMPLETED, summary_text, trial_result
from hil.outputs.writer import write_trial_outputs
from hil.pipeline.processor import TrialProcessor


class TrialSetupError(ValueError):
    """A trial that cannot start as asked (arguments, ports, viewer, table); the message says why."""


def truth_bias_ug(cfg: Config) -> list[float] | None:
    """The accelerometer bias the emulator injects (µg), for comparison in the outputs; None for real devices."""
    return list(cfg.imu.errors.accel_bias_ug) if cfg.imu.source == "emulator" else None


def output_dir(out: str | Path | None, cfg: Config) -> Path:
    """``--out``, else ``output.dir``, else ``runs/NAME-TIME``."""
    if out:
        return Path(out)
    return Path(cfg.output.dir) if cfg.output.dir else Path("runs") / f"{cfg.trial.name}-{time.strftime('%Y%m%d-%H%M%S')}"


@dataclass
class TrialOutcome:
    """A finished trial: its config, where its outputs go, the result.json document and the snapshots."""

    cfg: Config
    config_text: str
    out: Path
    result: dict
    snapshots: list[Snapshot]

    @property
    def ended(self) -> str:
        return self.result["ended"]

    @classmethod
    def of(cls, processor: TrialProcessor, cfg: Config, config_text: str, out: Path, ended: str = COMPLETED,
           truth: list[float] | None = None) -> TrialOutcome:
        """The outcome of a finished processor; ``ended`` says how the trial ended."""
        result = trial_result(cfg.trial.name, processor.estimator, processor.streams(), truth)
        result = {"trial": result["trial"], "ended": ended, **{k: v for k, v in result.items() if k != "trial"}}
        snapshots = processor.estimator.snapshots if processor.estimator is not None else []
        return cls(cfg, config_text, out, result, snapshots)

    def write(self, figures: bool = True) -> str:
        """Write every output and print the summary; returns PASS or FAIL against ``output.limits``."""
        outcome = write_trial_outputs(self.out, self.result, self.snapshots, self.cfg.output.limits,
                                      self.config_text, figures=figures and self.cfg.output.figures)
        print(summary_text(self.result, self.out))
        print(f"  report: {outcome} against output.limits ({self.out / 'report.html'})")
        return outcome
