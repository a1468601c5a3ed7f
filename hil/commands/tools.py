"""The commands around the trials: ``hil history``, ``campaign``, ``worker``, ``report``, ``decode``,
``emulate`` and ``ratetest``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def cmd_ratetest(args: argparse.Namespace) -> int:
    from hil.ratetest_command import ratetest_command

    return ratetest_command(args)


def cmd_history(args: argparse.Namespace) -> int:
    from hil.history.show import show_history

    return show_history(args.history, args.dut, args.since, args.json, Path(args.out) if args.out else None,
                        args.sync)


def cmd_campaign(args: argparse.Namespace) -> int:
    from hil.campaign.runner import run_campaign

    out = Path(args.out) if args.out else Path("runs") / f"campaign-{Path(args.spec).stem}"
    return run_campaign(args.spec, out, args.scheduler, args.workers, args.resume)


def cmd_worker(args: argparse.Namespace) -> int:
    from hil.campaign.workers import run_workers

    return run_workers(args.scheduler, args.nworkers, args.host)


def cmd_report(args: argparse.Namespace) -> int:
    from hil.outputs.result import verdict_exit_code
    from hil.outputs.trial_report import rebuild_report

    path, verdict = rebuild_report(Path(args.dir))
    print(path)
    return verdict_exit_code(verdict)


def cmd_decode(args: argparse.Namespace) -> int:
    import yaml

    from drivers.capture import decode_capture, detect_capture
    from hil.inputs import InputError

    options = {}
    for item in args.option:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError(f"--option {item}: expected KEY=VALUE")
        options[key] = yaml.safe_load(value)
    auto = args.protocol == "auto"
    protocol = detect_capture(args.file) if auto else args.protocol
    counters = decode_capture(protocol, args.file, out_csv=args.out, dbc=args.dbc, rate_hz=args.rate, **options)
    print(json.dumps({"protocol": protocol, **counters} if auto else counters))
    return 0


def cmd_emulate(args: argparse.Namespace) -> int:
    from emulators.command import emulate
    from hil.config import load_config
    from hil.inputs import InputError

    try:
        return emulate(load_config(args.config, units=True), args)
    except OSError as exc:  # e.g. a --link-dir that cannot be written
        raise InputError(str(exc)) from None
