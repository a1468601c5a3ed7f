"""A trial of several units on one table (docs/units.md): each unit's one-unit trial run by the one-unit runner
on its own config (:meth:`hil.config.Config.unit_configs`) into ``OUT/units/<name>/``, and the trial's index."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from hil.config import Config
from hil.outputs.units_index import UNITS_DIR, absent_entry, unit_entry, units_exit_code, write_units_index
from hil.trial.outcome import TrialOutcome

# runs one unit's trial: its one-unit config, that config's text (its config.yaml) and its output directory
RunUnit = Callable[[Config, str, Path], TrialOutcome]


@dataclass
class FixtureOutcome:
    """A finished trial of several units: the trial's name and directory, each unit's outcome by name, each
    unit's live view (a :class:`~hil.viewer.trial_viewer.TrialViewer`, the first one the viewer's owner) if any, the
    fixture's overview (a :class:`~hil.viewer.fixture_view.FixtureView`) if any, and once written the index
    result.json."""

    name: str
    out: Path
    units: dict[str, TrialOutcome]
    viewers: dict[str, object] = field(default_factory=dict)
    absent: dict[str, tuple[str | None, str]] = field(default_factory=dict)  # optional units: (dut_serial, why)
    overview: object | None = None
    index: dict | None = None  # OUT/result.json, once :meth:`write_index` wrote it

    def write_index(self) -> int:
        """Write OUT/result.json, report.html and junit.xml over the units' written outputs and the absent units;
        the exit code (:func:`~hil.outputs.units_index.units_exit_code`)."""
        doc = self.index = write_units_index(self.out, self.name, [
            *(unit_entry(name, outcome.result) for name, outcome in self.units.items()),
            *(absent_entry(name, serial, why) for name, (serial, why) in self.absent.items())])
        return units_exit_code(unit["verdict"] for unit in doc["units"])


def run_units(cfg: Config, out: Path, run_unit: RunUnit) -> FixtureOutcome:
    """Every unit's trial by ``run_unit``, in the order of ``units``, each in ``OUT/units/<name>/`` with its
    one-unit config as its config.yaml (that config alone reproduces the unit's trial)."""
    units = {}
    for name, unit_cfg in cfg.unit_configs().items():
        units[name] = run_unit(unit_cfg, unit_config_text(name, unit_cfg), out / UNITS_DIR / name)
    return FixtureOutcome(cfg.trial.name, out, units)


def recorded_units(source: str | Path) -> tuple[str, dict[str, Path]] | None:
    """The trial name and each unit's directory (its recording.mcap) of a units trial's directory, by the index
    result.json it wrote; None for any other source."""
    index = Path(source) / "result.json"
    try:
        doc = json.loads(index.read_text()) if index.is_file() else {}
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or not isinstance(doc.get("units"), list):
        return None
    return doc["trial"]["name"], {unit["name"]: Path(source) / unit["out_dir"] for unit in doc["units"]
                                  if unit["out_dir"]}


def unit_config_text(name: str, cfg: Config) -> str:
    """A unit's one-unit config as YAML (what it sets beyond the defaults)."""
    body = yaml.safe_dump(cfg.model_dump(mode="json", exclude_defaults=True), sort_keys=False)
    return f"# unit {name} of a units config, as a one-unit config (docs/units.md)\n{body}"
