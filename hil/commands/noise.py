"""``hil noise``: an acquisition (or a file) analysed for its Allan deviation into its claimed directory."""

from __future__ import annotations

import argparse
import sys
from datetime import datetime, timezone
from pathlib import Path

from hil.commands.trial_outputs import claimed, record_options


def cmd_noise(args: argparse.Namespace) -> int:
    out = Path(args.out) if args.out else Path("runs") / f"noise-{Path(args.source).stem}"
    with claimed(args, out, args.source, args.config, noise=True):
        units = _unit_sources(args, out)
        if units is None:
            return _noise(args, out)
        codes = [1 if source is None else _noise(argparse.Namespace(**{**vars(args), "source": str(source)}),
                                                 out / "units" / name) for name, source in units.items()]
        return 1 if 1 in codes else max(codes)


def _unit_sources(args: argparse.Namespace, out: Path) -> dict[str, Path | None] | None:
    """Each unit's source of a units config or a units trial's directory (docs/units.md), None for any other
    source: a recorded trial's unit directories; an emulated units config's unit configs (written as
    ``OUT/units/<name>/config.yaml``); a units config that reads devices, one acquisition of every unit into
    ``OUT/acquisition`` and each unit's directory there (None for a unit whose acquisition did not complete)."""
    from hil.trial.units import recorded_units

    path = Path(args.source)
    if path.is_dir():
        units = recorded_units(path)
        return None if units is None else units[1]
    if path.suffix not in (".yaml", ".yml") and path.exists():
        return None
    from hil.config import load_config
    from hil.inputs import resolve_path

    cfg = load_config(resolve_path(path), units=True)
    if not cfg.units:
        return None
    if args.viewer != "none" or args.rerun:
        from hil.inputs import InputError

        raise InputError(f"--viewer {args.viewer}: a units config is analysed without a live view so far")
    if all(unit.imu.source == "emulator" for unit in cfg.units) and cfg.turntable.source == "emulator":
        return _unit_configs(cfg, out)
    return _acquired_units(args, cfg, out)


def _unit_configs(cfg, out: Path) -> dict[str, Path]:
    """Each unit's one-unit config, written as ``OUT/units/<name>/config.yaml``."""
    from hil.trial.units import unit_config_text

    written = {}
    for name, unit in cfg.unit_configs().items():
        path = out / "units" / name / "config.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(unit_config_text(name, unit))
        written[name] = path
    return written


def _acquired_units(args: argparse.Namespace, cfg, out: Path) -> dict[str, Path | None]:
    """One acquisition of every unit, the table held still, into ``OUT/acquisition`` (its index and each unit's
    trial outputs); each unit's directory there, None for a unit whose acquisition did not complete."""
    from hil.commands.trial_outputs import finish_units
    from hil.outputs.result import COMPLETED
    from hil.trial.noise_acquisition import ACQUISITION_DIR, held_still
    from hil.trial.units_live import run_units_live

    directory = out / ACQUISITION_DIR
    fixture = run_units_live(held_still(cfg), Path(args.source), directory, args.duration, "1", args.quiet)
    finish_units(argparse.Namespace(**{**vars(args), "no_history": True, "no_figures": True}), fixture)
    sources: dict[str, Path | None] = {}
    for name, outcome in fixture.units.items():
        sources[name] = directory / "units" / name if outcome.ended == COMPLETED else None
        if sources[name] is None:
            print(f"hil: noise: unit {name}: the acquisition {outcome.ended}: no noise analysis", file=sys.stderr)
    return sources


def _noise(args: argparse.Namespace, out: Path) -> int:
    """``hil noise`` into its claimed directory ``out``."""
    from hil.outputs.noise import noise_summary
    from hil.outputs.record import noise_record
    from hil.trial.noise_acquisition import AcquisitionFailed
    from hil.trial.noise_runner import AllanSettings, NoiseSource, run_noise

    given = record_options(args)
    view = _view(args, out)
    try:
        doc = run_noise(NoiseSource(args.source, args.config, args.duration, args.quiet), out,
                        AllanSettings(taus=args.taus, detrend=args.detrend), figure=not args.no_figures,
                        export=args.export, view=view,
                        record=lambda block: noise_record(given, args.source, block, args.started,
                                                          datetime.now(timezone.utc)))
    except AcquisitionFailed as exc:
        print(f"hil: noise: {exc}", file=sys.stderr)
        return exc.exit_code
    finally:
        if view is not None:
            view.close()
    print(noise_summary(doc, out))
    if not args.no_history:
        from hil.history.entry import NOISE, noise_figures, trial_row
        from hil.history.filing import file_trial

        result = {"trial": doc["trial"], "ended": "completed", "record": doc["record"]}
        file_trial(args.history, trial_row(NOISE, out, result, None, noise_figures(doc)))
    if view is not None:
        from hil.trial.viewer_feed import finish_viewer

        finish_viewer(view)
    return 0


def _view(args: argparse.Namespace, out: Path):
    """The noise view ``--viewer`` asks for (``--rerun``: ``save``), or None."""
    mode = "save" if args.rerun and args.viewer == "none" else args.viewer
    if mode == "none":
        return None
    from hil.outputs.noise import ADEV_UNITS
    from hil.trial.viewer_feed import started_view
    from hil.viewer.allan_view import AllanView  # rerun only when a view is asked for

    return started_view(lambda: AllanView(mode, out, ADEV_UNITS, args.bind), mode)
