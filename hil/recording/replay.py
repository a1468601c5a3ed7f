"""Replay: a recording's chunks through the same processing as the live run, in the same order."""

from __future__ import annotations

from pathlib import Path

import yaml

from hil.config import Config, ConfigError, parse_config
from hil.pipeline.processor import TrialProcessor
from hil.recording.csv_input import DataError
from hil.recording.recorder import Recording, read_recording
from hil.trial.viewer_feed import Viewer, ViewerSinks, health

RECORDING_NAME = "recording.mcap"


def recording_path(source: str | Path) -> Path:
    """The recording file of a run directory, or the file itself."""
    path = Path(source)
    return path / RECORDING_NAME if path.is_dir() else path


def recorded_config(recording: Recording, source: str | Path) -> Config:
    """The trial config stored in a recording."""
    try:
        data = yaml.safe_load(recording.metadata["config"])
    except (KeyError, yaml.YAMLError) as exc:
        raise ConfigError(f"{source}: the recording holds no readable config ({exc})") from None
    return parse_config(data, f"{source} (recorded config)")


def open_recording(source: str | Path) -> tuple[Recording, Config]:
    """A run directory's or a file's recording, read once, and the trial config stored in it."""
    path = recording_path(source)
    try:
        recording = read_recording(path)
    except OSError as exc:
        raise DataError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:  # not a recording; the message names the file
        raise DataError(str(exc)) from None
    return recording, recorded_config(recording, path)


def replay(recording: Recording, cfg: Config, viewer: Viewer | None = None) -> TrialProcessor:
    """Process a recording's items with its config (and log them to ``viewer``); returns the finished
    processor."""
    duration = recording.metadata.get("duration_s")
    sinks = ViewerSinks(viewer)
    scale = recording.metadata.get("time_scale", "1.0")
    time_scale = float(scale) if scale else None
    processor = TrialProcessor(cfg, float(duration) if duration else None, time_scale, sinks.on_snapshot,
                               sinks.on_aligned)
    sinks.processor = processor
    for item in recording.items:
        processor.feed(item)
    processor.finish()
    if viewer is not None and processor.estimator is not None:
        viewer.log_health(processor.trial_time, health(processor))
    return processor
