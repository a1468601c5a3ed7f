"""Opening a recording for replay: a run directory or its recording file, and the trial config stored in it."""

from __future__ import annotations

from pathlib import Path

import yaml

from hil.config import Config, ConfigError, parse_config
from hil.recording.csv_input import DataError
from hil.recording.recorder import Recording, RecordingReader

RECORDING_NAME = "recording.mcap"


def recording_path(source: str | Path) -> Path:
    """The recording file of a run directory, or the file itself."""
    path = Path(source)
    return path / RECORDING_NAME if path.is_dir() else path


def recorded_config(recording: Recording | RecordingReader, source: str | Path) -> Config:
    """The trial config stored in a recording."""
    try:
        data = yaml.safe_load(recording.metadata["config"])
    except (KeyError, yaml.YAMLError) as exc:
        raise ConfigError(f"{source}: the recording holds no readable config ({exc})") from None
    return parse_config(data, f"{source} (recorded config)")


def open_recording(source: str | Path) -> tuple[RecordingReader, Config]:
    """A run directory's or a file's recording, opened for one pass over its items (the metadata read, the
    items not yet), and the trial config stored in it."""
    path = recording_path(source)
    try:
        recording = RecordingReader(path)
    except OSError as exc:
        raise DataError.unreadable(path, exc) from None
    except ValueError as exc:  # not a recording; the message names the file
        raise DataError(str(exc)) from None
    try:
        return recording, recorded_config(recording, path)
    except BaseException:
        recording.close()
        raise


def recorded_pace(recording: Recording | RecordingReader) -> tuple[float | None, float | None]:
    """The recorded trial's duration (s, None: none) and its devices' speed (None: ``--speed max``), which a
    replay's processor takes as the live one did (the receive times mean what they meant live)."""
    duration = recording.metadata.get("duration_s")
    scale = recording.metadata.get("time_scale", "1.0")
    return float(duration) if duration else None, float(scale) if scale else None
