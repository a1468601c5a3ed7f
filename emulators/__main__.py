"""``python -m emulators CONFIG ...``: the emulated devices as a process (see :mod:`emulators.process`).

What :func:`emulators.process.spawn_emulator` starts; ``hil emulate`` runs the same devices.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from emulators.process import parse_speed, run_emulator
from hil.config import ConfigError, load_config


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emulators",
                                     description="``hil emulate``: run the emulated devices until stopped, "
                                                 "signalled or done.")
    parser.add_argument("config", type=Path)
    parser.add_argument("--ports-file", type=Path)
    parser.add_argument("--speed", type=parse_speed, default=1.0, help="multiple of real time, or max")
    parser.add_argument("--duration", type=float, help="s; default trial.duration_s")
    parser.add_argument("--wait-readers", action="store_true",
                        help="start the pulse train once every port has a reader")
    parser.add_argument("--stats-file", type=Path, help="write the run's statistics here as JSON at the end")
    parser.add_argument("--hold", action="store_true",
                        help="after the pulse train, keep the devices (the acl port) up until stopped")
    args = parser.parse_args(argv)
    try:
        stats = run_emulator(load_config(args.config), args.ports_file, args.speed, args.duration,
                             wait_readers=args.wait_readers, stats_file=args.stats_file, hold=args.hold)
    except (ConfigError, OSError) as exc:
        print(f"emulator: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(stats.as_dict()), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
