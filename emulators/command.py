"""The ``hil emulate`` command, also ``python -m emulators``: its options, the run, and the statistics it
reports on stderr, one line a device, whether it ends by itself or on a signal."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from emulators.bench import EmulatorStats
    from hil.config import Config


def speed_option(text: str) -> str:
    """``--speed``: X times real time or ``max``, checked as it is parsed (a bad one is a usage error)."""
    from emulators.process import parse_speed

    try:
        parse_speed(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def positive(text: str) -> float:
    """A duration or a rate: a finite number above 0, checked as it is parsed (anything else is a usage error)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a number above 0, got {text}")
    return value


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of the command, after its config argument."""
    parser.add_argument("--ports-file", type=Path, help="write the ports as JSON here once they are open")
    parser.add_argument("--link-dir", type=Path, metavar="DIR",
                        help="publish the serial ports as stable links DIR/imu and DIR/turntable_data, named so in "
                             "the ports (a later emulator on the same DIR points them at its own ports)")
    parser.add_argument("--stats-file", type=Path, help="write the run's statistics here as JSON at the end")
    parser.add_argument("--speed", default="1", type=speed_option, help="X times real time, or 'max' (default 1)")
    parser.add_argument("--duration", type=positive, help="seconds of trial time (default: trial.duration_s)")
    parser.add_argument("--wait-readers", action="store_true",
                        help="hold the pulse train until every port has a reader that has emptied its input "
                             "(default: stream at once, as hardware does; frames nobody reads are lost and counted)")


def emulate(cfg: Config, args: argparse.Namespace, hold: bool = False) -> int:
    """Run the emulated devices of ``cfg`` as the options say, then print their statistics; exit code 0."""
    from emulators.process import EmulatorRun, run_emulator

    run = EmulatorRun(args.speed, args.duration, args.wait_readers, hold, args.stats_file, args.link_dir)
    stats = run_emulator(cfg, run, args.ports_file)
    print(summary(stats), file=sys.stderr)
    return 0


def summary(stats: EmulatorStats) -> str:
    """The run in lines: the pulses, then per device the frames written, lost unread and faults per kind."""
    lines = [f"emulator: {stats.pulses} pulses in {stats.elapsed_s:.1f} s" + (", stopped" if stats.stopped else "")]
    for name, device in stats.devices.items():
        faults = ", ".join(f"{kind} {n}" for kind, n in device.faults.items() if n) or "none"
        lines.append(f"emulator: {name}: {device.frames} frames written, {device.lost_unread} lost unread, "
                     f"faults: {faults}")
    return "\n".join(lines)
