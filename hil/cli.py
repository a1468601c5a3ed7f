"""The ``hil`` command line: the arguments parsed (:mod:`hil.arguments`), it calls the command they name
(:mod:`hil.commands`).

Each command imports its runner when it runs, inside its ``cmd_*`` function: the parser alone starts in
about 40 ms (``hil --help``, a refused argument), where importing every runner would cost about 1.1 s before
anything is checked (docs/architecture.md, "Where each trial kind plugs in")."""

from __future__ import annotations

import os
import signal
import sys
import threading

from hil import interrupted_at_start

if __name__ == "__main__":  # python -m hil.cli (the console script's start is hil's, in hil/__init__.py)
    signal.signal(signal.SIGINT, interrupted_at_start)

import argparse  # noqa: E402 (after the handler: a Ctrl-C during these imports is one line too)
from datetime import datetime, timezone  # noqa: E402
from types import FrameType  # noqa: E402

from hil.arguments import build_parser  # noqa: E402
from hil.commands.noise import cmd_noise  # noqa: E402
from hil.commands.tools import (cmd_campaign, cmd_decode, cmd_emulate, cmd_history, cmd_ratetest,  # noqa: E402
                                cmd_report, cmd_worker)
from hil.commands.trials import cmd_calibrate, cmd_estimate, cmd_replay, cmd_run, cmd_simulate  # noqa: E402


def cmd_plan(args: argparse.Namespace) -> int:
    """``hil plan``: its steps run the commands of :data:`COMMANDS`."""
    from hil.plan.runner import run_plan

    return run_plan(args, COMMANDS)


# the function of each command, by the name the parser gives it
COMMANDS = {"run": cmd_run, "calibrate": cmd_calibrate, "ratetest": cmd_ratetest, "replay": cmd_replay,
            "simulate": cmd_simulate, "estimate": cmd_estimate, "noise": cmd_noise, "history": cmd_history,
            "campaign": cmd_campaign, "worker": cmd_worker, "report": cmd_report, "decode": cmd_decode,
            "emulate": cmd_emulate, "plan": cmd_plan}


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (default: the command line's) names; its exit code. Ctrl-C at any moment but a
    trial's (which ends the trial as interrupted, :mod:`hil.trial.stop_signals`), from the parsing of the
    arguments on, is one line and exit 130."""
    try:
        if signal.getsignal(signal.SIGINT) is interrupted_at_start:
            signal.signal(signal.SIGINT, _interrupt)  # caught below from here on
        return _command(argv)
    except BaseException as exc:
        if not _interrupted(exc):
            raise
        _INTERRUPT_CAUGHT.set()
        print("hil: interrupted", file=sys.stderr)
        return 130


_INTERRUPT_CAUGHT = threading.Event()
RESEND_S = 0.5  # s between the sendings of a Ctrl-C that has not ended the command yet
DEFER_S = 0.02  # s before a Ctrl-C that came inside the import system is sent again
IMPORT_SYSTEM = "<frozen importlib"  # the file names of its frames


def _interrupt(signum: int, frame: FrameType | None) -> None:
    """Ctrl-C: KeyboardInterrupt, caught in :func:`main`. Some places lose one: the import system's module-lock
    callbacks print "Exception ignored" with a traceback and go on. Inside the import system the signal is sent
    again :data:`DEFER_S` later instead; anywhere else it is raised and sent again every :data:`RESEND_S` until
    one reaches :func:`main`, or a trial's own handler takes it (and ends the trial as interrupted)."""
    deferred = frame is not None and frame.f_code.co_filename.startswith(IMPORT_SYSTEM)
    timer = threading.Timer(DEFER_S if deferred else RESEND_S, _resend, (signum,))
    timer.daemon = True
    timer.start()
    if not deferred:
        raise KeyboardInterrupt


def _resend(signum: int) -> None:
    if not _INTERRUPT_CAUGHT.is_set():
        os.kill(os.getpid(), signum)


def _interrupted(exc: BaseException | None) -> bool:
    """Whether ``exc`` is a Ctrl-C's KeyboardInterrupt or was raised by one (Python wraps one raised in a class
    body's ``__set_name__`` into a RuntimeError, for instance)."""
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def _command(argv: list[str] | None) -> int:
    """The arguments parsed and their command run; bad input is one line and exit 2."""
    args = build_parser().parse_args(argv)
    args.func, args.started = COMMANDS[args.command], datetime.now(timezone.utc)
    from hil.inputs import InputError  # no schema yet: a command that starts a child does so first

    try:
        return args.func(args)
    except InputError as exc:
        print(f"hil: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
