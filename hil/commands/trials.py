"""The trial commands: ``hil run``, ``calibrate``, ``replay``, ``simulate`` and ``estimate``. The offline ones
start their child processes (the figure process, the simulation process) before the schemas and the numerics
load, so that the children's imports overlap the parent's (docs/architecture.md, "Where each trial kind plugs in")."""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.commands.trial_outputs import claimed, finish, finish_units, trial_config, viewer_options


def cmd_run(args: argparse.Namespace) -> int:
    cfg, out = trial_config(args, units=True)
    with claimed(args, out, args.config):
        if cfg.units:
            from hil.trial.units_live import UnitsCommand, run_units_live

            return finish_units(args, run_units_live(cfg, Path(args.config), out, args.duration, args.speed,
                                                     args.quiet, UnitsCommand(), viewer_options(args)))
        from hil.trial.live_runner import run_live

        return finish(args, *run_live(cfg, Path(args.config), out, args.duration, args.speed, viewer_options(args),
                                      args.quiet))


def cmd_calibrate(args: argparse.Namespace) -> int:
    cfg, out = trial_config(args, units=True)
    with claimed(args, out, args.config):
        if cfg.units:
            return _calibrate_units(args, cfg, out)
        if args.simulate:
            from hil.trial.calibration_simulation import run_calibration_simulation

            return finish(args, *run_calibration_simulation(cfg, Path(args.config).read_text(), out,
                                                            viewer_options(args)))
        from hil.trial.calibration_runner import run_calibration

        return finish(args, *run_calibration(cfg, Path(args.config), out, args.speed, viewer_options(args),
                                             args.quiet))


def _calibrate_units(args: argparse.Namespace, cfg, out: Path) -> int:
    """``hil calibrate`` of a units config: one schedule for the fixture, a calibration per unit (docs/units.md);
    ``--simulate``: each unit's calibration simulated in turn, in this process."""
    _no_units_viewer(args)
    if args.simulate:
        from hil.trial.calibration_simulation import run_calibration_simulation
        from hil.trial.units import run_units
        from hil.trial.viewer_feed import ViewerOptions

        cfg.emulated_only(args.config, "hil calibrate --simulate")
        return finish_units(args, run_units(cfg, out, lambda unit, text, unit_out: run_calibration_simulation(
            unit, text, unit_out, ViewerOptions())[0]))
    from hil.trial.calibration_runner import run_units_calibration

    return finish_units(args, run_units_calibration(cfg, Path(args.config), out, args.speed, args.quiet))


def cmd_replay(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess  # started first: matplotlib loads while the trial runs

    with FigureProcess() as figures:
        from hil.inputs import InputError
        from hil.recording.replay import recording_path
        from hil.trial.offline import run_replay

        from hil.trial.units import recorded_units

        units = recorded_units(args.source)
        recorded = Path(args.source) if units else recording_path(args.source).parent
        out = Path(args.out) if args.out else recorded / "replay"
        if out.resolve() == recorded.resolve():
            raise InputError(f"--out {out}: the recording's own directory; a replay writes beside it (default "
                             f"{recorded / 'replay'})")
        with claimed(args, out):
            if units:
                return _replay_units(args, out, *units)
            return finish(args, *run_replay(args.source, out, viewer_options(args)), figures)


def _replay_units(args: argparse.Namespace, out: Path, name: str, recorded: dict[str, Path]) -> int:
    """``hil replay`` of a units trial's directory: each unit's recording replayed into ``OUT/units/<name>/``, and
    the trial's index (docs/units.md)."""
    from hil.outputs.units_index import UNITS_DIR
    from hil.trial.offline import run_replay
    from hil.trial.units import FixtureOutcome
    from hil.trial.viewer_feed import ViewerOptions

    _no_units_viewer(args)
    return finish_units(args, FixtureOutcome(name, out, {
        unit: run_replay(source, out / UNITS_DIR / unit, ViewerOptions())[0] for unit, source in recorded.items()}))


def cmd_simulate(args: argparse.Namespace) -> int:
    from emulators.simulation_process import SimulationProcess  # first: its child imports the emulator meanwhile

    with SimulationProcess() as simulation, _figure_process() as figures:
        cfg, out = trial_config(args, units=True)
        cfg.emulated_only(args.config, "hil simulate")
        if not cfg.units:
            simulation.start(cfg)  # its first batches computed while the estimator's modules load
        from hil.trial.offline import run_simulation

        with claimed(args, out, args.config):
            if cfg.units:
                return _simulate_units(args, cfg, out)
            outcome = run_simulation(cfg, Path(args.config).read_text(), out, viewer_options(args), simulation)
            return finish(args, *outcome, figures)


def _figure_process():
    """A :class:`~hil.outputs.figure_process.FigureProcess`, imported (with numpy) once the simulation's child is
    started: that child's imports are on the way to the first batch, the figure process's are not."""
    from hil.outputs.figure_process import FigureProcess

    return FigureProcess()


def _simulate_units(args: argparse.Namespace, cfg, out: Path) -> int:
    """``hil simulate`` of a units config: each unit simulated and estimated in this process, one after the other
    (docs/units.md); no live view."""
    from hil.trial.offline import run_simulation
    from hil.trial.units import run_units
    from hil.trial.viewer_feed import ViewerOptions

    _no_units_viewer(args)
    return finish_units(args, run_units(cfg, out, lambda unit, text, unit_out: run_simulation(
        unit, text, unit_out, ViewerOptions())[0]))


def _no_units_viewer(args: argparse.Namespace) -> None:
    """A units trial runs without a live view so far (docs/units.md): ``--viewer spawn|serve`` is refused, and
    ``save`` saves no .rrd."""
    from hil.inputs import InputError

    if args.viewer in ("spawn", "serve"):
        raise InputError(f"--viewer {args.viewer}: a units trial runs without a live view so far")


def cmd_estimate(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess

    with FigureProcess() as figures:
        from hil.trial.offline import run_csv

        cfg, out = trial_config(args)
        with claimed(args, out, args.config, args.data):
            return finish(args, run_csv(cfg, Path(args.config).read_text(), args.data, out), None, figures)
