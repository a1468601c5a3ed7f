"""The runners whose data is already there: a recording (``hil replay``), the emulator's truth and sensor
errors (``hil simulate``), and increments exported from other software (``hil estimate``). Each feeds
the same processor as a live trial and returns one :class:`~hil.trial.outcome.TrialOutcome`."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from hil.config import Config
from hil.outputs.record import recorded_block
from hil.outputs.result import COMPLETED, TrialEnd
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.progress import Finished
from hil.pipeline.settings import PipelineSettings
from hil.trial.outcome import TrialOutcome, emulated_truth
from hil.trial.viewer_feed import Viewer, ViewerFeed, ViewerOptions, open_viewer
from hil.vocabulary import TrialKind

if TYPE_CHECKING:
    from emulators.simulation_process import SimulationProcess
    from hil.recording.recorder import Recording, RecordingReader


@dataclass
class ReplayOutcome(TrialOutcome):
    """A replay's outcome: its trial's record is the recorded trial's (unit, part, operator, station, notes), and
    it is filed in the history as a replay of that trial (``replay_of``: its run directory), not a trial."""

    replay_of: Path | None = None

    def filed_as(self) -> tuple[str, dict, Path | None]:
        return TrialKind.SWING, self.result, self.replay_of


def run_replay(source: str | Path, out: str | Path | None, options: ViewerOptions
               ) -> tuple[ReplayOutcome, Viewer | None]:
    """A recording's chunks through the processing of the live run, in the same order, read as they are fed."""
    from hil.recording.replay import open_recording, recording_path  # the recorder and mcap: a replay's only

    path = recording_path(source)
    out = Path(out) if out else path.parent / "replay"
    recording, cfg = open_recording(source)
    cfg = cfg.model_copy(update={"record": recorded_block(path, cfg.record)})  # the recorded unit
    with recording:
        viewer = open_viewer(options, cfg, out, blocking=True)
        finished = replay_recording(recording, cfg, viewer)
    # how the recording ends is known once every item has been read
    if recording.truncated:
        print(f"hil: {source}: the recording ends inside a record (cut short); replayed up to it", file=sys.stderr)
    ended = how_it_ended(recording)
    outcome = TrialOutcome.of(finished, cfg, recording.metadata["config"], out, ended, emulated_truth(cfg))
    return ReplayOutcome(**vars(outcome), replay_of=path.parent), viewer


def how_it_ended(recording: RecordingReader | Recording) -> str:
    """How the recorded trial ended (its ``trial_end`` record), for a recording read to its end."""
    return recording.ended or str(TrialEnd.early("the recording was cut short") if recording.truncated
                                  else TrialEnd(COMPLETED))


def replay_recording(recording: RecordingReader | Recording, cfg: Config, viewer: Viewer | None = None
                     ) -> Finished:
    """The pipeline's end of a recording's items fed in their order (and logged to ``viewer``); a
    :class:`~hil.recording.recorder.RecordingReader` is read item by item as they are fed."""
    from hil.recording.replay import recorded_pace  # the recorder and mcap: a recording's only

    processor = TrialProcessor(PipelineSettings.of(cfg), *recorded_pace(recording), [ViewerFeed(viewer).on_progress])
    for item in recording:
        processor.feed(item)
    finished = processor.finish()
    if viewer is not None and finished.estimator is not None:
        viewer.log_health(finished.progress.trial_time, finished.progress.health)
    return finished


def run_simulation(cfg: Config, config_text: str, out: Path, options: ViewerOptions,
                   process: SimulationProcess | None = None) -> tuple[TrialOutcome, Viewer | None]:
    """The emulator's samples, already aligned, in batches into the processor: no transport, no alignment.
    The batches are computed by ``process`` ahead of the estimator, on another core (``hil simulate``), or
    without one in line (a campaign's run: its worker has no core to spare)."""
    if process is None:
        from emulators.simulation import Simulation  # hil simulate's process imports it in its child only

        batches = Simulation.from_config(cfg).batches()
    else:
        batches = process.batches(cfg)
    viewer = open_viewer(options, cfg, out, blocking=True)
    processor = TrialProcessor(PipelineSettings.of(cfg), listeners=[ViewerFeed(viewer, snapshots=False).on_progress])
    for batch in batches:
        processor.feed_batch(batch)
    finished = processor.finished()
    if viewer is not None and finished.estimator is not None:
        viewer.log_snapshots(finished.snapshots)  # as columns, in one go
    return TrialOutcome.of(finished, cfg, config_text, out, truth=emulated_truth(cfg)), viewer


def run_csv(cfg: Config, config_text: str, data: str | Path, out: Path) -> TrialOutcome:
    """Increments (and table angles, if present) from a CSV into the processor; no truth."""
    from hil.recording.csv_input import read_increments_csv  # hil estimate's only

    processor = TrialProcessor(PipelineSettings.of(cfg))
    processor.feed_batch(read_increments_csv(data, cfg))
    return TrialOutcome.of(processor.finished(), cfg, config_text, out)
