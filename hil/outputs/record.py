"""result.json's ``record``: who tested which unit, where, with which software and config, when, on which ports
(docs/contracts.md, "result.json"). Filed with every trial's outputs, in report.html's header and junit.xml's
``<properties>``."""

from __future__ import annotations

import functools
import hashlib
import json
import socket
import subprocess
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from hil import package_version
from hil.config import Config, RecordConfig
from hil.inputs import resolve_path
from hil.vocabulary import Port

PROPERTIES = ("dut_part", "dut_serial", "station", "operator", "software_version", "commit", "config_sha256",
              "started_utc", "ended_utc", "host", "controller")  # what junit.xml and the report's header show


@functools.cache
def source_commit() -> str | None:
    """The git commit of the checkout the package runs from (``-dirty`` when changed), None outside one; asked
    of git once a process (a live trial's record is taken at its start and at its end)."""
    root = Path(__file__).resolve().parents[2]
    try:
        run = subprocess.run(["git", "-C", str(root), "describe", "--always", "--dirty", "--abbrev=40"],
                             capture_output=True, text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return run.stdout.strip() or None if run.returncode == 0 else None


def run_record(fields: dict[str, Any], config_text: str | None, started: datetime, ended: datetime) -> dict[str, Any]:
    """The record of a run: ``fields`` (``record``'s config keys) and the software, config digest, times and host."""
    return {**fields, "software_version": package_version(), "commit": source_commit(),
            "config_sha256": None if config_text is None else hashlib.sha256(config_text.encode()).hexdigest(),
            "started_utc": started.isoformat(timespec="seconds"), "ended_utc": ended.isoformat(timespec="seconds"),
            "host": socket.gethostname()}


@dataclass(frozen=True)
class RecordSource:
    """What a trial's record takes from its config, read once by :meth:`of`: the ``record`` block, the ports the
    config names (the record's when the devices were not found on others) and the table's controller (None without
    a command port)."""

    block: RecordConfig
    ports: dict[str, Any]
    controller: str | None

    @classmethod
    def of(cls, cfg: Config) -> RecordSource:
        """The record's source of a one-unit config."""
        imu = cfg.imu.can.model_dump() if cfg.imu.source == "can" and cfg.imu.can else cfg.imu.port
        ports = {Port.IMU: imu, Port.TABLE_DATA: cfg.turntable.data_port, Port.TABLE_CMD: cfg.turntable.command_port}
        return cls(cfg.record, ports, cfg.turntable.controller if cfg.turntable.command_port else None)

    def devices(self, ports: dict[str, Any] | None) -> dict[str, Any]:
        """The record's ``ports`` (``ports`` as found, else the config's) and ``controller``."""
        return {"ports": self.ports if ports is None else ports, "controller": self.controller}


def trial_record(source: RecordSource, config_text: str, started: datetime, ended: datetime, out: Path
                 ) -> dict[str, Any]:
    """The record of a trial (its config's ``source``, its YAML ``config_text``) that ran from ``started`` to
    ``ended`` (aware datetimes, UTC) into ``out``: the ports its recording says it read (those of the emulator it
    started), else the config's."""
    recorded = _start_record(out / "recording.mcap") or {}
    ports, imu_config = (json.loads(recorded[key]) if recorded.get(key) else None for key in ("ports", "imu_config"))
    return {**run_record(source.block.model_dump(), config_text, started, ended), **source.devices(ports),
            "imu_config": imu_config}


def start_record(source: RecordSource, config_text: str, ports: dict[str, Any] | None,
                 imu_config: dict[str, Any] | None = None) -> dict[str, Any]:
    """The record of a trial as it starts (the recording's metadata): :func:`trial_record`'s fields but
    ``ended_utc``, with the ``ports`` the devices were found on (None: the config's) and what the IMU said of its
    configuration (``imu_config``: :func:`hil.trial.imu_config.check_imu_config`; None: not asked)."""
    now = datetime.now(timezone.utc)
    record = run_record(source.block.model_dump(), config_text, now, now)
    del record["ended_utc"]
    return {**record, **source.devices(ports), "imu_config": imu_config}


def _start_record(recording: Path) -> dict[str, str] | None:
    """:func:`~hil.recording.recorder.read_start_record` of ``recording``; None when there is none (a simulation's
    outputs), without loading the recorder and mcap."""
    if not recording.is_file():
        return None
    from hil.recording.recorder import read_start_record  # mcap: only for a trial that recorded

    return read_start_record(recording)


def recorded_block(recording: Path, block: RecordConfig) -> RecordConfig:
    """``block`` with the fields of the record the trial in ``recording`` started with (its unit, part, operator,
    station and notes, as the command line gave them over its config); ``block`` for a file without one."""
    recorded = _start_record(recording) or {}
    return block.model_copy(update={key: recorded[key] or None for key in RecordConfig.model_fields if key in recorded})


def noise_record(given: dict[str, str | None], source: str | Path, block: RecordConfig | None, started: datetime,
                 ended: datetime) -> dict[str, Any]:
    """noise.json's record: the ``record`` ``block`` of the source's config (a config source's, as loaded for the
    run; None: for a recording the one its trial started with, for a CSV none) overridden by the options ``given``
    (dut_serial, operator, station), the source's digest when it is a file (a config, a shipped config's name
    included, or a CSV; None for a run directory), no ports or controller of its own."""
    path = resolve_path(source)
    recording = path / "recording.mcap" if path.is_dir() else path
    block = block if block is not None else recorded_block(recording, RecordConfig())
    fields = block.model_dump() | {key: value for key, value in given.items() if value is not None}
    text = path.read_text(errors="replace") if path.is_file() and path.suffix in (".yaml", ".yml", ".csv") else None
    return {**run_record(fields, text, started, ended), "source": str(source), "ports": None, "controller": None}
