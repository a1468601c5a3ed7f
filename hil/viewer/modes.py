"""The ``--viewer`` modes and the default one, apart from :mod:`hil.viewer.trial_viewer` so the parser need not import Rerun."""

from __future__ import annotations

import os

VIEWER_MODES = ("spawn", "serve", "save", "none")


def default_viewer_mode() -> str:
    """``spawn`` when a display exists (DISPLAY or WAYLAND_DISPLAY), otherwise ``save``."""
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return "spawn"
    return "save"
