"""``python -m emulators CONFIG ...``: the emulated devices as a process (see :mod:`emulators.process`).

What :func:`emulators.process.spawn_emulator` starts; ``hil emulate`` runs the same command
(:mod:`emulators.command`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from emulators.command import add_options, emulate
from hil.config import ConfigError, load_config


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emulators",
                                     description="``hil emulate``: run the emulated devices until stopped, "
                                                 "signalled or done.")
    parser.add_argument("config", type=Path)
    add_options(parser)
    parser.add_argument("--hold", action="store_true",
                        help="after the pulse train, keep the devices (the table's command port) up until stopped")
    args = parser.parse_args(argv)
    try:
        return emulate(load_config(args.config, units=True), args, hold=args.hold)
    except (ConfigError, OSError) as exc:
        print(f"emulator: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
