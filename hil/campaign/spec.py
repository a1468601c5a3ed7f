"""A campaign's SPEC: ``{base: CONFIG, runs: N, seed: S, kind: K, sweep: {dotted.key: [values], ...}}`` (YAML,
safe loading), validated, and expanded into its runs: every combination of the sweep, N seeds each. ``kind``
(default ``swing``) is the simulated trial each run is (:mod:`hil.campaign.kinds`).

The seeds are ``numpy.random.SeedSequence(S).spawn(N)``, one per run index and shared by every sweep point
(common random numbers: two points differ by the swept values, not by their noise), so a campaign is the
same on any cluster, and a campaign with more runs keeps the seeds of the first ones.
"""

from __future__ import annotations

import copy
import itertools
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from emulators.servo_simulation import ServoSimulation
from emulators.simulation import Simulation
from hil.campaign.task import RunTask, point_label
from hil.config import Config, ConfigError, InputError, parse_config
from hil.config_types import describe_validation
from hil.inputs import resolve_path
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.trial.calibration_outcome import checked_schedule
from hil.trial.outcome import TrialSetupError


class SpecError(InputError, ValueError):
    """A campaign SPEC that cannot be used; the message names the key and the reason."""


DEFAULT_KIND = "swing"


class CampaignSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    base: str  # the trial config every run starts from: relative to the SPEC's directory, or a shipped name
    runs: int = Field(gt=0)  # seeds per sweep point
    seed: int = Field(0, ge=0)  # entropy of the SeedSequence
    kind: Literal["swing", "noise", "calibration"] = DEFAULT_KIND  # the simulated trial of every run (kinds.KINDS)
    sweep: dict[str, list[Any]] = {}

    @field_validator("sweep")
    @classmethod
    def _values_listed(cls, sweep: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for key, values in sweep.items():
            if not values:
                raise ValueError(f"{key}: expected a non-empty list of values")
        return sweep

    def as_dict(self) -> dict[str, Any]:
        """The SPEC for summary.json; ``kind`` only when it is not the default (a swing campaign's summary is
        as it was before campaigns had kinds)."""
        return self.model_dump(exclude={"kind"} if self.kind == DEFAULT_KIND else None)


@dataclass(frozen=True)
class Campaign:
    """A validated SPEC: the sweep points (their values) and the tasks of every run."""

    spec: CampaignSpec
    path: Path
    points: list[dict[str, Any]]
    tasks: list[RunTask]


def _submodel(annotation: Any) -> type[BaseModel] | None:
    """The model a field holds (``CanConfig | None`` holds CanConfig), or None for a value."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        models = [m for m in map(_submodel, typing.get_args(annotation)) if m is not None]
        return models[0] if len(models) == 1 else None
    return None


def check_key(key: str) -> None:
    """Raise :class:`SpecError` unless ``key`` names a key of the trial config (``imu.errors.accel_noise_ug``)."""
    model: type[BaseModel] | None = Config
    parts = key.split(".")
    for k, part in enumerate(parts):
        if model is None:
            raise SpecError(f"sweep.{key}: {'.'.join(parts[:k])} is a value, not a block of keys")
        if part not in model.model_fields:
            raise SpecError(f"sweep.{key}: unknown key {'.'.join(parts[:k + 1])!r} of the trial config")
        model = _submodel(model.model_fields[part].annotation)


def set_key(config: dict, key: str, value: Any) -> None:
    """Set the dotted ``key`` of a config mapping, making the blocks on the way."""
    *blocks, last = key.split(".")
    node = config
    for part in blocks:
        if not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    node[last] = copy.deepcopy(value)


def run_seeds(seed: int, runs: int) -> list[int]:
    """The trial seed of each run index: the first 63 bits of each child of ``SeedSequence(seed)``."""
    return [int(child.generate_state(1, np.uint64)[0] >> np.uint64(1))
            for child in np.random.SeedSequence(seed).spawn(runs)]


def _read_yaml(path: Path, what: str) -> Any:
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SpecError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise SpecError(f"{path}: not valid YAML: {' '.join(str(exc).split())}") from None


def _base_path(spec_path: Path, base: str) -> Path:
    """``base`` beside the SPEC if it is there, else as :func:`hil.inputs.resolve_path` finds it."""
    beside = spec_path.parent / base
    return beside if beside.exists() else resolve_path(base)


def _check_point(config: dict, label: str, source: str, kind: str) -> None:
    """The trial config of a point, checked as its kind's trial sets it up (the emulator and the processor,
    with ``imu.calibration`` read; a calibration's schedule within the table's limits and the in-process
    servo); a ConfigError or TrialSetupError names the point."""
    try:
        cfg = parse_config(config, source)
        cfg.emulated_only(source, "hil campaign")
        if kind == "calibration":
            checked_schedule(cfg)
            ServoSimulation.from_config(cfg)
        else:
            Simulation.from_config(cfg)
        TrialProcessor(PipelineSettings.of(cfg))
    except (ConfigError, TrialSetupError) as exc:
        raise SpecError(f"{source}: sweep point {label}: {str(exc).removeprefix(source + ': ')}") from None


def load_campaign(path: str | Path) -> Campaign:
    """Read, validate and expand a SPEC; every sweep point's config is checked before anything runs."""
    path = resolve_path(path)
    data = _read_yaml(path, "campaign spec")
    if not isinstance(data, dict):
        raise SpecError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    try:
        spec = CampaignSpec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(f"{path}: {describe_validation(exc)}") from None
    for key in spec.sweep:
        try:
            check_key(key)
        except SpecError as exc:
            raise SpecError(f"{path}: {exc}") from None
    base_path = _base_path(path, spec.base)
    base = _read_yaml(base_path, "base config")
    if not isinstance(base, dict):
        raise SpecError(f"{base_path}: expected a mapping at the top level, got {type(base).__name__}")
    keys = list(spec.sweep)
    points = [dict(zip(keys, combo)) for combo in itertools.product(*(spec.sweep[k] for k in keys))]
    seeds = run_seeds(spec.seed, spec.runs)
    tasks = []
    for p, values in enumerate(points):
        config = copy.deepcopy(base)
        for key, value in values.items():
            set_key(config, key, value)
        _check_point(config, point_label(values), str(path), spec.kind)
        for r, seed in enumerate(seeds):
            run_config = copy.deepcopy(config)
            set_key(run_config, "trial.seed", seed)
            tasks.append(RunTask(f"p{p:03d}-r{r:04d}", p, r, seed, values, run_config))
    return Campaign(spec, path, points, tasks)
