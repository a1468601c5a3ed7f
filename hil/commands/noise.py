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
        return _noise(args, out)


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
                        record=lambda cfg: noise_record(given, args.source, cfg, args.started,
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
