"""``hil noise CONFIG`` where the config reads devices: a record acquired from them as ``hil run`` acquires it
(recorded, with a trial's outputs in ``OUT/acquisition``), a commanded table held still at the motion's centre
positions. The record is analysed only when its streams pass their own limits (frames lost or corrupt, samples
filled, gated or without angles): a noise figure of a broken record is a wrong answer."""

from __future__ import annotations

from pathlib import Path

from hil.config import Config
from hil.inputs import InputError
from hil.outputs.measurements import FAIL, STREAM_MEASUREMENTS, format_value
from hil.outputs.result import COMPLETED
from hil.trial.live_runner import run_live
from hil.trial.viewer_feed import ViewerOptions

ACQUISITION_DIR = "acquisition"


class AcquisitionFailed(InputError):
    """The record could not be acquired whole; ``exit_code`` as a trial's: 1 ended early, 3 over a limit."""

    def __init__(self, message: str, exit_code: int) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def held_still(cfg: Config) -> Config:
    """The config with a commanded table's motion made ``static`` (each gimbal at its ``center_deg``); a table the
    harness does not command moves as its console says, and the analysis takes a motion out by its angles."""
    if cfg.turntable.command_port is None:
        return cfg
    motion = cfg.turntable.motion.model_copy(update={"kind": "static"})
    return cfg.model_copy(update={"turntable": cfg.turntable.model_copy(update={"motion": motion})})


def acquire(cfg: Config, config_path: Path, out: Path, duration: float | None, quiet: bool = False) -> Path:
    """Acquire and record ``duration`` s (default ``trial.duration_s``) from the devices into
    ``OUT/acquisition`` and write its trial outputs; returns that directory. Raises :class:`AcquisitionFailed`
    when the trial ended early or a stream measurement FAILs its limit."""
    if duration is None and cfg.trial.duration_s is None:
        raise AcquisitionFailed(f"{config_path}: trial.duration_s or --duration: how long a record to acquire", 2)
    directory = out / ACQUISITION_DIR
    outcome, _ = run_live(held_still(cfg), config_path, directory, duration, "1", ViewerOptions(), quiet)
    judged = outcome.write(figures=False)
    if outcome.ended != COMPLETED:
        raise AcquisitionFailed(f"the acquisition {outcome.ended}: no noise analysis ({directory / 'report.html'})", 1)
    failed = [m for m in judged.measurements if m.name in STREAM_MEASUREMENTS and m.outcome == FAIL]
    if failed:
        named = ", ".join(f"{m.name} {format_value(m.value)} (limit {m.limit})" for m in failed)
        report = directory / "report.html"
        raise AcquisitionFailed(f"the record's streams FAIL {named}: no noise analysis ({report})", 3)
    return directory
