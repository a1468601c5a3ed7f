"""The ``--viewer`` modes, the default one and the options of a trial's view, apart from
:mod:`hil.viewer.trial_viewer` so the parser need not import Rerun."""

from __future__ import annotations

import os
from dataclasses import dataclass

VIEWER_MODES = ("spawn", "serve", "save", "none")


def default_viewer_mode() -> str:
    """``spawn`` when a display exists (DISPLAY or WAYLAND_DISPLAY), otherwise ``save``."""
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return "spawn"
    return "save"


@dataclass(frozen=True)
class ViewerOptions:
    """``--viewer`` and ``--bind``; ``layout`` the blueprint: ``trial``, or ``calibration`` (the trial's views
    and the calibration's, :mod:`hil.viewer.calibration_view`); a plan's step: ``connect`` the gRPC URL of the
    plan's viewer (None: none) and ``plan`` the plan's document (:mod:`hil.viewer.plan_view`)."""

    mode: str = "none"
    bind: str = "127.0.0.1"
    layout: str = "trial"
    connect: str | None = None
    plan: str | None = None
