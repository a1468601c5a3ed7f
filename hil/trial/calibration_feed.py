"""The calibration schedule's progress and each window's residual, as they happen, to the viewer.

A window's residual is the one before calibration (the fit comes at the end): its mean output minus the
reference of the error-free model with zero offsets zero, at its encoder angles (the "before" of
calibration.html's figure): the specific force of a dwell against gravity, the angular rate of every window
against the earth rate plus the gimbal rates.
"""

from __future__ import annotations

import numpy as np

from hil.estimation.accel_calibration import raw_force_residuals
from hil.estimation.calibration_model import Window
from hil.estimation.calibration_schedule import Dwell, Plateau, Schedule
from hil.estimation.gyro_calibration import raw_rate_residuals
from hil.frames import Earth, TableGeometry
from hil.trial.calibration_settings import CalibrationSettings
from hil.units import DEG_PER_H, UG


class CalibrationFeed:
    """``on_step`` and ``on_window`` of :class:`hil.trial.calibration_sequence.CalibrationSequence`, forwarded
    to a viewer's ``log_calibration_step`` and ``log_calibration_window``."""

    def __init__(self, viewer, steps: list[Dwell | Plateau], earth: Earth, geometry: TableGeometry) -> None:
        self.viewer = viewer
        self.steps = list(steps)
        self.earth = earth
        self.geometry = geometry

    def on_step(self, t: float, index: int) -> None:
        self.viewer.log_calibration_step(t, index, self.steps)

    def on_window(self, t: float, index: int, window: Window) -> None:
        accel, gyro = window_residual(window, self.earth, self.geometry)
        self.viewer.log_calibration_window(t, None if accel is None else accel / UG, gyro / DEG_PER_H)


def window_residual(window: Window, earth: Earth, geometry: TableGeometry) -> tuple[np.ndarray | None, np.ndarray]:
    """(specific force residual (3,) m/s^2 of a dwell, None for a plateau; angular rate residual (3,) rad/s)
    against the error-free model (module docstring)."""
    gyro = raw_rate_residuals([window], earth, geometry)[0]
    return (raw_force_residuals([window], earth, geometry)[0] if window.static else None), gyro


def sequence_views(viewer, schedule: Schedule, settings: CalibrationSettings) -> dict:
    """The ``on_step`` and ``on_window`` arguments of a calibration sequence that log to ``viewer`` (none
    without a viewer), the residuals at the site and through the table's geometry of ``settings``."""
    if viewer is None:
        return {}
    feed = CalibrationFeed(viewer, list(schedule.dwells) + list(schedule.plateaus), settings.earth, settings.geometry)
    return {"on_step": feed.on_step, "on_window": feed.on_window}
