"""Replay: a recording's chunks through the same processing as the live run, in the same order."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import yaml

from hil.config import Config, ConfigError, parse_config
from hil.estimation.online import Snapshot
from hil.processing import TrialProcessor
from hil.recording import Recording, read_recording
from hil.samples import AlignedSample

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


def replay(source: str | Path, on_snapshot: Callable[[Snapshot], None] | None = None,
           on_aligned: Callable[[list[AlignedSample]], None] | None = None
           ) -> tuple[TrialProcessor, Recording, Config]:
    """Process a recording; returns the finished processor, the recording and its config."""
    path = recording_path(source)
    try:
        recording = read_recording(path)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    cfg = recorded_config(recording, path)
    duration = recording.metadata.get("duration_s")
    processor = TrialProcessor(cfg, float(duration) if duration else None, on_snapshot, on_aligned)
    for item in recording.items:
        processor.feed(item)
    processor.finish()
    return processor, recording, cfg
