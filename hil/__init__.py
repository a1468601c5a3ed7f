"""The turntable IMU harness (``hil``); :func:`child_env` for the ``python -m`` children of its commands."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent  # the directory of the packages hil, drivers and emulators


def child_env(**extra: str) -> dict[str, str]:
    """This process's environment with :data:`ROOT` first on PYTHONPATH (a ``python -m`` child imports this
    same code, installed or not) and the variables ``extra``."""
    path = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
    return {**os.environ, "PYTHONPATH": path, **extra}
