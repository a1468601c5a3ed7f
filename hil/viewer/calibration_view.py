"""The Rerun views of ``hil calibrate``: the schedule's progress on the 3-D table and each window's residual
as it is measured.

Progress: one marker a dwell position around the IMU case, in the body frame at the direction of gravity
in that position (``C_n^b [0, 0, -1]``, radius ``MARKER_RADIUS``), so the table brings a position's marker
straight below the IMU when it gets there; done positions green, the commanded one highlighted, the
others grey; the step number and the count (``calibration/step``) and a line of text a step
(``calibration/log``). Residuals, before calibration (the error-free model, zero offsets zero: the fit
comes at the end): the specific force of each dwell against gravity (µg, ``calibration/residual/accel_ug``
and a bar chart per axis over the positions, ``calibration/bars/<axis>``), the angular rate of every
window against the earth and gimbal rates (°/h, ``calibration/residual/gyro_dph``).
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hil.estimation.calibration_schedule import Dwell, Plateau
from hil.frames import TableGeometry
from hil.units import DEG
from hil.viewer.blueprint import AXES, AXIS_COLORS, TIMELINE, TRUTH_COLOR

MARKERS = "world/table/outer/middle/inner/imu/calibration/positions"
MARKER_RADIUS = 0.45  # scene units: outside the IMU case, inside the inner ring
DONE, PENDING = (77, 175, 74), (150, 150, 150)
CURRENT = TRUTH_COLOR


def calibration_views() -> rrb.Vertical:
    """The blueprint column of the calibration views."""
    return rrb.Vertical(
        rrb.TimeSeriesView(origin="/calibration/step", name="calibration step"),
        rrb.TimeSeriesView(origin="/calibration/residual/accel_ug", name="specific force residual, before (µg)"),
        rrb.Horizontal(*(rrb.BarChartView(origin=f"/calibration/bars/{a}", name=f"{a} residual per position (µg)")
                         for a in AXES)),
        rrb.TimeSeriesView(origin="/calibration/residual/gyro_dph", name="angular rate residual, before (°/h)"),
        rrb.TextLogView(origin="/calibration/log", name="schedule"),
        name="calibration",
    )


def marker_positions(geometry: TableGeometry, steps: list[Dwell | Plateau]) -> np.ndarray:
    """(N_dwells, 3): each dwell's marker in the body frame (the module docstring)."""
    angles = np.array([s.angles for s in steps if isinstance(s, Dwell)])
    c_bn = geometry.attitude_matrix(angles)[0]
    return MARKER_RADIUS * (np.array([0.0, 0.0, -1.0]) @ c_bn)


def step_text(steps: list[Dwell | Plateau], index: int) -> str:
    """``step 3 of 24: position 3 at (0, 90, 0) deg`` or ``... plateau 2: inner at -10 deg/s``."""
    step = steps[index]
    head = f"step {index + 1} of {len(steps)}: "
    if isinstance(step, Plateau):
        number = index - sum(isinstance(s, Dwell) for s in steps) + 1
        gimbal = ("outer", "middle", "inner")[step.axis]
        return head + f"plateau {number}: {gimbal} at {step.rate / DEG:g} deg/s"
    angles = ", ".join(f"{a / DEG:g}" for a in step.angles)
    return head + f"position {index + 1} at ({angles}) deg"


class CalibrationLog:
    """The calibration entities of one recording: the schedule's markers and the dwells' residuals so far."""

    def __init__(self, rec: rr.RecordingStream, geometry: TableGeometry, steps: list[Dwell | Plateau]) -> None:
        self.rec = rec
        self.steps = list(steps)
        self.markers = marker_positions(geometry, self.steps)
        self.accel_history: list[np.ndarray] = []
        rec.log("calibration/step", rr.SeriesLines(names=["step", "steps"], colors=[CURRENT, PENDING]), static=True)
        for path in ("calibration/residual/accel_ug", "calibration/residual/gyro_dph"):
            rec.log(path, rr.SeriesPoints(names=list(AXES), colors=[AXIS_COLORS[a] for a in AXES]), static=True)

    def step(self, t: float, index: int) -> None:
        """Step ``index`` (0-based) commanded at trial time ``t``."""
        rec, n = self.rec, len(self.markers)
        rec.set_time(TIMELINE, duration=t)
        colors = [DONE if k < index else CURRENT if k == index else PENDING for k in range(n)]
        radii = [0.04 if k == index else 0.025 for k in range(n)]
        rec.log(MARKERS, rr.Points3D(self.markers, colors=colors, radii=radii, labels=[str(k + 1) for k in range(n)]))
        rec.log("calibration/step", rr.Scalars([index + 1, len(self.steps)]))
        rec.log("calibration/log", rr.TextLog(step_text(self.steps, index)))

    def window(self, t: float, accel_ug: np.ndarray | None, gyro_dph: np.ndarray) -> None:
        """One window's residuals at trial time ``t`` (its end): the accelerometers' of a dwell (None for a
        plateau), then the bar charts of every dwell's so far, and the gyros'."""
        rec = self.rec
        rec.set_time(TIMELINE, duration=t)
        if accel_ug is not None:
            rec.log("calibration/residual/accel_ug", rr.Scalars(accel_ug))
            self.accel_history.append(np.asarray(accel_ug, dtype=float))
            history = np.array(self.accel_history)
            for k, a in enumerate(AXES):
                rec.log(f"calibration/bars/{a}", rr.BarChart(history[:, k], color=AXIS_COLORS[a]))
        rec.log("calibration/residual/gyro_dph", rr.Scalars(gyro_dph))
