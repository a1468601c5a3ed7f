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
from hil.trial.calibration_settings import CalibrationSettings
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


def _listed_model(annotation: Any) -> type[BaseModel] | None:
    """The model of each item of a field that lists models (``list[UnitConfig] | None``), else None."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        models = [m for m in map(_listed_model, typing.get_args(annotation)) if m is not None]
        return models[0] if len(models) == 1 else None
    if typing.get_origin(annotation) is list:
        return _submodel(typing.get_args(annotation)[0])
    return None


def check_key(key: str) -> None:
    """Raise :class:`SpecError` unless ``key`` names a key of the trial config (``imu.errors.accel_noise_ug``); a
    list of models is stepped into by an item's index (``units.1.imu.errors.accel_bias_ug``)."""
    model: type[BaseModel] | None = Config
    listed: type[BaseModel] | None = None  # the item model when the part before was a list of models
    parts = key.split(".")
    for k, part in enumerate(parts):
        if listed is not None:
            if not part.isdigit():
                raise SpecError(f"sweep.{key}: {'.'.join(parts[:k + 1])}: expected an index of the list "
                                f"{'.'.join(parts[:k])} (0, 1, ...)")
            model, listed = listed, None
            continue
        if model is None:
            raise SpecError(f"sweep.{key}: {'.'.join(parts[:k])} is a value, not a block of keys")
        if part not in model.model_fields:
            raise SpecError(f"sweep.{key}: unknown key {'.'.join(parts[:k + 1])!r} of the trial config")
        annotation = model.model_fields[part].annotation
        model, listed = _submodel(annotation), _listed_model(annotation)


def set_key(config: dict, key: str, value: Any) -> None:
    """Set the dotted ``key`` of a config mapping, making the blocks on the way; an index (``units.1``) steps
    into a list the mapping has, a :class:`SpecError` naming the key when it has no such list or item."""
    parts = key.split(".")
    node: Any = config
    for k, part in enumerate(parts):
        index: Any = _index(node, key, ".".join(parts[:k]), part) if isinstance(node, list) else part
        if k == len(parts) - 1:
            node[index] = copy.deepcopy(value)
        elif parts[k + 1].isdigit():
            if not isinstance(_child(node, index), list):
                raise SpecError(f"sweep.{key}: {'.'.join(parts[:k + 2])}: the base config has no "
                                f"{'.'.join(parts[:k + 1])} to index")
            node = node[index]
        else:
            if not isinstance(_child(node, index), dict):
                node[index] = {}
            node = node[index]


def _child(node: dict | list, index: Any) -> Any:
    return node[index] if isinstance(node, list) else node.get(index)


def _index(items: list, key: str, name: str, part: str) -> int:
    """``part`` (digits) as an index of ``items``, the list ``name`` of the config; a SpecError naming ``key``
    when the list has no such item."""
    if int(part) >= len(items):
        indices = f"0 to {len(items) - 1}" if items else "none"
        raise SpecError(f"sweep.{key}: {name}.{part}: index out of range: the base config has {len(items)} {name} "
                        f"({indices})")
    return int(part)


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


def _check_point(config: dict, label: str, source: str, kind: str) -> Config:
    """The trial config of a point, checked as its kind's trial sets it up (the emulator and the processor,
    with ``imu.calibration`` read; a calibration's schedule within the table's limits and the in-process
    servo), each unit's one-unit config of a units config; a ConfigError or TrialSetupError names the point."""
    try:
        cfg = parse_config(config, source, units=True)
        cfg.emulated_only(source, "hil campaign")
        for trial in cfg.unit_configs().values() or [cfg]:
            if kind == "calibration":
                checked_schedule(CalibrationSettings.of(trial))
                ServoSimulation.from_config(trial)
            else:
                Simulation.from_config(trial)
            TrialProcessor(PipelineSettings.of(trial))
    except (ConfigError, TrialSetupError) as exc:
        raise SpecError(f"{source}: sweep point {label}: {str(exc).removeprefix(source + ': ')}") from None
    return cfg


def _point_config(base: dict, values: dict[str, Any], source: str) -> dict:
    """The base config with a point's swept values set."""
    config = copy.deepcopy(base)
    for key, value in values.items():
        try:
            set_key(config, key, value)
        except SpecError as exc:
            raise SpecError(f"{source}: {exc}") from None
    return config


def _run_tasks(p: int, values: dict[str, Any], config: dict, seeds: list[int], cfg: Config) -> list[RunTask]:
    """A point's tasks (``cfg``: its config checked): its config with each run's ``trial.seed``. A units config's
    run is a task per unit, the unit's one-unit config as ``hil simulate`` of the run's units config runs it
    (:meth:`Config.unit_configs`: each unit's seed drawn from the run's)."""
    tasks = []
    for r, seed in enumerate(seeds):
        run_config = copy.deepcopy(config)
        set_key(run_config, "trial.seed", seed)
        if not cfg.units:
            tasks.append(RunTask(f"p{p:03d}-r{r:04d}", p, r, seed, values, run_config))
            continue
        units = Config.model_validate(run_config).unit_configs()
        tasks += [RunTask(f"p{p:03d}-r{r:04d}-{name}", p, r, seed, values,
                          unit.model_dump(mode="json", exclude_defaults=True), name) for name, unit in units.items()]
    return tasks


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
        config = _point_config(base, values, str(path))
        cfg = _check_point(config, point_label(values), str(path), spec.kind)
        tasks += _run_tasks(p, values, config, seeds, cfg)
    return Campaign(spec, path, points, tasks)
