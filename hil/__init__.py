"""The turntable IMU harness (``hil``); :func:`child_env` and :func:`end_child` for the ``python -m`` children of
its commands."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterable
from pathlib import Path
from typing import IO

ROOT = Path(__file__).resolve().parent.parent  # the directory of the packages hil, drivers and emulators


def child_env(**extra: str) -> dict[str, str]:
    """This process's environment with :data:`ROOT` first on PYTHONPATH (a ``python -m`` child imports this
    same code, installed or not) and the variables ``extra``."""
    path = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
    return {**os.environ, "PYTHONPATH": path, **extra}


def end_child(child: subprocess.Popen, files: Iterable[IO]) -> None:
    """Kill ``child`` if it still runs, reap it, and close ``files`` (its pipes)."""
    child.kill()
    child.wait()
    for file in files:
        file.close()
