"""The turntable IMU harness (``hil``); :func:`child_env` and :func:`end_child` for the ``python -m`` children of
its commands; :func:`interrupted_at_start`, the Ctrl-C of the ``hil`` command until :func:`hil.cli.main` runs."""

from __future__ import annotations

import os
import signal
import sys


def interrupted_at_start(signum: int, frame: object) -> None:
    """Ctrl-C while the ``hil`` command starts, before :func:`hil.cli.main` catches it: nothing is open yet; one
    line and exit 130."""
    os.write(2, b"hil: interrupted\n")
    os._exit(130)


if os.path.basename((getattr(sys, "argv", None) or [""])[0]) == "hil":  # the console script starting
    signal.signal(signal.SIGINT, interrupted_at_start)  # first: before this package's imports

from pathlib import Path  # noqa: E402
from typing import TYPE_CHECKING  # noqa: E402

if TYPE_CHECKING:
    import subprocess
    from collections.abc import Iterable
    from typing import IO

ROOT = Path(__file__).resolve().parent.parent  # the directory of the packages hil, drivers and emulators


def child_env(**extra: str) -> dict[str, str]:
    """This process's environment with :data:`ROOT` first on PYTHONPATH (a ``python -m`` child imports this
    same code, installed or not) and the variables ``extra``."""
    path = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
    return {**os.environ, "PYTHONPATH": path, **extra}


def package_version() -> str:
    """This package's installed version, "unknown" when it is not installed (run from a checkout)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("turntable-hil")
    except PackageNotFoundError:
        return "unknown"


def end_child(child: subprocess.Popen, files: Iterable[IO]) -> None:
    """Kill ``child`` if it still runs, reap it, and close ``files`` (its pipes)."""
    child.kill()
    child.wait()
    for file in files:
        file.close()
