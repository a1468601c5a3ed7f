"""A test plan's YAML (docs/plans.md): ``{name, config, steps}`` read, every step checked against the plan's config
before anything moves, and the ``repeat`` blocks unrolled into the numbered steps the plan runs and files."""

from __future__ import annotations

import copy
import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hil.config import Config, ConfigError, load_config, parse_config
from hil.inputs import InputError, resolve_path

RATE_TESTS = ("scale_factor", "frequency_response")  # hil ratetest, their settings the config's block of that name
TRIAL_KINDS = ("swing", "calibrate", "noise", *RATE_TESTS)
KINDS = ("power", "soak", "wait", "repeat", *TRIAL_KINDS)
POWER_ACTIONS = ("on", "off", "cycle")
ON_FAILURE = ("stop", "continue")
STEP_EXTRAS = {"power": ("off_s",)}  # keys a step takes beside its kind and on_failure


@dataclass(frozen=True)
class Step:
    """One step of the unrolled plan: its number (from 1), kind, parameters (``overrides`` of the config for a
    swing or calibrate step), what an early end does, and the ``repeat`` block and pass it belongs to."""

    index: int
    kind: str
    params: Any
    on_failure: str = "stop"
    off_s: float | None = None
    block: int | None = None  # the index of the repeat block's first step
    repeat: int | None = None  # the pass of that block, from 1
    config: Config | None = None  # a trial step's config, the overrides applied
    data: dict = field(default_factory=dict)  # that config as a mapping, written beside the step's outputs

    @property
    def out_name(self) -> str:
        """The step's output directory under the plan's: ``NN-<kind>``."""
        return f"{self.index:02d}-{self.kind}"

    @property
    def duration_s(self) -> float:
        """Seconds of trial time the step takes, as scheduled."""
        if self.kind == "swing":
            return float(self.config.trial.duration_s)
        if self.kind == "calibrate":
            from hil.estimation.calibration_schedule import schedule_duration, schedule_from_config

            return schedule_duration(schedule_from_config(self.config.calibration), self.config.turntable.limits)
        if self.kind == "noise":
            return float(self.params["duration_s"])
        if self.kind in RATE_TESTS:
            settings = getattr(self.config, self.kind)
            points = len(settings.rates_dps) * 2 if self.kind == "scale_factor" else len(settings.frequencies_hz)
            return float(points * len(settings.axes) * (settings.dwell_s + settings.settle_s))
        if self.kind == "wait":
            return float(self.params["s"])
        if self.kind == "soak":  # at least: the chamber's way there comes first
            return float(self.params["for_s"])
        return float(self.off_s or 0.0)


@dataclass(frozen=True)
class Plan:
    """A plan as read: its name, the config it runs, the base config's mapping, the unrolled steps, the digest
    of its text (a resumed plan must be the same plan)."""

    name: str
    path: Path
    config_path: Path
    config: Config
    steps: list[Step]
    sha256: str


def load_plan(path: str | Path) -> Plan:
    """Read and check the plan at ``path``: an :class:`~hil.inputs.InputError` naming the step's index and key
    for anything a step cannot run with."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
        doc = yaml.safe_load(text)
    except (OSError, yaml.YAMLError) as exc:
        raise InputError(f"{path}: cannot read the plan: {getattr(exc, 'strerror', None) or exc}") from None
    if not isinstance(doc, dict) or set(doc) - {"name", "config", "steps"} or not {"name", "config", "steps"} <= set(doc):
        raise InputError(f"{path}: a plan is a mapping of exactly name, config and steps")
    config_path = _config_path(path, doc["config"])
    config = load_config(config_path)
    with config_path.open(encoding="utf-8") as stream:
        base = yaml.safe_load(stream)
    steps = _unroll(path, doc["steps"], base, [])
    if not steps:
        raise InputError(f"{path}: steps: the plan has no step")
    return Plan(str(doc["name"]), path, config_path, config, steps, hashlib.sha256(text.encode()).hexdigest())


def _config_path(plan: Path, named: Any) -> Path:
    """The plan's config: beside the plan file, else as :func:`hil.inputs.resolve_path` finds it."""
    if not isinstance(named, str):
        raise InputError(f"{plan}: config: expected the path of a trial config")
    beside = plan.parent / named
    found = beside if beside.is_file() else resolve_path(named)
    if not found.is_file():
        raise InputError(f"{plan}: config: {named}: no such file")
    return found


def _unroll(plan: Path, entries: Any, base: dict, steps: list[Step], block: int | None = None,
            repeat: int | None = None) -> list[Step]:
    """Append the steps of ``entries`` to ``steps`` (a repeat block's, its passes one after another)."""
    if not isinstance(entries, list):
        raise InputError(f"{plan}: steps: expected a list")
    for entry in entries:
        index = len(steps) + 1
        kind, params, extras = _kind(plan, index, entry)
        if kind == "repeat":
            times, inner = _repeat(plan, index, params)
            for k in range(1, times + 1):
                _unroll(plan, inner, base, steps, index, k)
            continue
        steps.append(_step(plan, index, kind, params, extras, base, block, repeat))
    return steps


def _kind(plan: Path, index: int, entry: Any) -> tuple[str, Any, dict]:
    """The kind of the step ``entry``, its parameters and its other keys (on_failure, off_s)."""
    if not isinstance(entry, dict):
        raise InputError(f"{plan}: step {index}: expected a mapping such as {{swing: {{}}}}")
    kinds = [key for key in entry if key in KINDS]
    unknown = [key for key in entry if key not in KINDS and key != "on_failure"
               and not (kinds and key in STEP_EXTRAS.get(kinds[0], ()))]
    if unknown:
        raise InputError(f"{plan}: step {index}: {unknown[0]}: unknown step kind or key (kinds: {', '.join(KINDS)})")
    if len(kinds) != 1:
        raise InputError(f"{plan}: step {index}: expected one step kind, got {', '.join(kinds) or 'none'}")
    extras = {key: value for key, value in entry.items() if key != kinds[0]}
    if extras.get("on_failure", "stop") not in ON_FAILURE:
        raise InputError(f"{plan}: step {index}: on_failure: {extras['on_failure']}: expected stop or continue")
    return kinds[0], entry[kinds[0]], extras


def _repeat(plan: Path, index: int, params: Any) -> tuple[int, list]:
    if not isinstance(params, dict) or set(params) != {"times", "steps"}:
        raise InputError(f"{plan}: step {index}: repeat: expected {{times, steps}}")
    times = params["times"]
    if not isinstance(times, int) or isinstance(times, bool) or times < 1:
        raise InputError(f"{plan}: step {index}: repeat.times: {times}: expected a whole number from 1")
    return times, params["steps"]


def _step(plan: Path, index: int, kind: str, params: Any, extras: dict, base: dict, block: int | None,
          repeat: int | None) -> Step:
    """The checked step ``index`` of ``kind``."""
    where = f"{plan}: step {index}: {kind}"
    common = {"index": index, "kind": kind, "on_failure": extras.get("on_failure", "stop"), "block": block,
              "repeat": repeat}
    if kind == "power":
        return Step(params=_power(where, params, extras), off_s=extras.get("off_s"), **common)
    if kind == "soak":
        keys = ("temperature_c", "stable_within_c", "for_s", "timeout_s")
        if not isinstance(params, dict) or set(params) != set(keys) or not all(_number(params[k]) for k in keys):
            raise InputError(f"{where}: expected {{{', '.join(keys)}}}, numbers")
        if params["stable_within_c"] <= 0 or params["for_s"] < 0 or params["timeout_s"] <= 0:
            raise InputError(f"{where}: stable_within_c and timeout_s above 0, for_s 0 or more")
        return Step(params=params, **common)
    if kind in ("wait", "noise"):
        key = "s" if kind == "wait" else "duration_s"
        if not isinstance(params, dict) or set(params) != {key} or not _seconds(params[key]):
            raise InputError(f"{where}: expected {{{key}: seconds}}")
        return Step(params=params, config=_config(where, base, {}), data=base, **common)
    overrides = params if params is not None else {}
    if not isinstance(overrides, dict):
        raise InputError(f"{where}: expected a mapping of config overrides")
    if kind in RATE_TESTS:  # the settings of the config's block of that name
        overrides = {kind: overrides}
    data = merged(base, overrides, where)
    return Step(params=overrides, config=_config(where, data, overrides), data=data, **common)


def _power(where: str, action: Any, extras: dict) -> str:
    if action is True:  # YAML reads a bare on as true, off as false
        action = "on"
    elif action is False:
        action = "off"
    if action not in POWER_ACTIONS:
        raise InputError(f"{where}: {action}: expected on, off or cycle")
    if (action == "cycle") != ("off_s" in extras):
        raise InputError(f"{where}: off_s: a power cycle takes off_s (seconds off), and only a cycle")
    if action == "cycle" and not _seconds(extras["off_s"]):
        raise InputError(f"{where}: off_s: {extras['off_s']}: expected seconds, 0 or more")
    return action


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _seconds(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0


def merged(base: dict, overrides: dict, where: str, known: dict | None = None, prefix: str = "") -> dict:
    """``base`` with ``overrides`` applied key by key; a key the config's schema does not have (``known``: the
    base config with its defaults) is refused, naming it."""
    known = parse_config(base).model_dump() if known is None else known
    out = copy.deepcopy(base)
    for key, value in overrides.items():
        if not isinstance(known, dict) or key not in known:
            raise InputError(f"{where}: {prefix}{key}: the config has no such key")
        if isinstance(value, dict) and isinstance(known[key], dict):
            out[key] = merged(out.get(key) or {}, value, where, known[key], f"{prefix}{key}.")
        else:
            out[key] = value
    return out


def _config(where: str, data: dict, overrides: dict) -> Config:
    try:
        return parse_config(data, "the config with the step's overrides" if overrides else "the config")
    except ConfigError as exc:
        raise InputError(f"{where}: {exc}") from None
