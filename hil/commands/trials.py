"""The trial commands: ``hil run``, ``calibrate``, ``replay``, ``simulate`` and ``estimate``. The offline ones
start their child processes (the figure process, the simulation process) before the schemas and the numerics
load, so that the children's imports overlap the parent's (docs/architecture.md, "Where each trial kind plugs in")."""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.commands.trial_outputs import claimed, finish, finish_units, trial_config, viewer_options


def cmd_run(args: argparse.Namespace) -> int:
    from hil.trial.live_runner import run_live

    cfg, out = trial_config(args)
    with claimed(args, out, args.config):
        return finish(args, *run_live(cfg, Path(args.config), out, args.duration, args.speed, viewer_options(args),
                                      args.quiet))


def cmd_calibrate(args: argparse.Namespace) -> int:
    cfg, out = trial_config(args)
    with claimed(args, out, args.config):
        if args.simulate:
            from hil.trial.calibration_simulation import run_calibration_simulation

            return finish(args, *run_calibration_simulation(cfg, Path(args.config).read_text(), out,
                                                            viewer_options(args)))
        from hil.trial.calibration_runner import run_calibration

        return finish(args, *run_calibration(cfg, Path(args.config), out, args.speed, viewer_options(args),
                                             args.quiet))


def cmd_replay(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess  # started first: matplotlib loads while the trial runs

    with FigureProcess() as figures:
        from hil.inputs import InputError
        from hil.recording.replay import recording_path
        from hil.trial.offline import run_replay

        recorded = recording_path(args.source).parent
        out = Path(args.out) if args.out else recorded / "replay"
        if out.resolve() == recorded.resolve():
            raise InputError(f"--out {out}: the recording's own directory; a replay writes beside it (default "
                             f"{recorded / 'replay'})")
        with claimed(args, out):
            return finish(args, *run_replay(args.source, out, viewer_options(args)), figures)


def cmd_simulate(args: argparse.Namespace) -> int:
    from emulators.simulation_process import SimulationProcess  # first: its child imports the emulator meanwhile
    from hil.outputs.figure_process import FigureProcess

    with SimulationProcess() as simulation, FigureProcess() as figures:
        from hil.trial.offline import run_simulation

        cfg, out = trial_config(args, units=True)
        cfg.emulated_only(args.config, "hil simulate")
        with claimed(args, out, args.config):
            if cfg.units:
                return _simulate_units(args, cfg, out)
            outcome = run_simulation(cfg, Path(args.config).read_text(), out, viewer_options(args), simulation)
            return finish(args, *outcome, figures)


def _simulate_units(args: argparse.Namespace, cfg, out: Path) -> int:
    """``hil simulate`` of a units config: each unit simulated and estimated in this process, one after the other
    (docs/units.md); no live view."""
    from hil.inputs import InputError
    from hil.trial.offline import run_simulation
    from hil.trial.units import run_units
    from hil.trial.viewer_feed import ViewerOptions

    if args.viewer != ViewerOptions.mode:
        raise InputError(f"--viewer {args.viewer}: a units config is simulated without a live view so far")
    return finish_units(args, run_units(cfg, out, lambda unit, text, unit_out: run_simulation(
        unit, text, unit_out, ViewerOptions())[0]))


def cmd_estimate(args: argparse.Namespace) -> int:
    from hil.outputs.figure_process import FigureProcess

    with FigureProcess() as figures:
        from hil.trial.offline import run_csv

        cfg, out = trial_config(args)
        with claimed(args, out, args.config, args.data):
            return finish(args, run_csv(cfg, Path(args.config).read_text(), args.data, out), None, figures)
