"""The temperatures of a trial's view (deg C): the IMU's own, once a second of trial time, and a chamber's reading
and set point as the harness takes and sends them, stamped with the trial time of the pipeline's latest progress
(the chamber's controller knows no trial time). Each entity gets its style with its first row, so a trial without
a chamber, or with an IMU that reports no temperature, has none of its entities."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import rerun as rr

PERIOD_S = 1.0  # the IMU's temperature is logged once every this many seconds of trial time at most
IMU, CHAMBER_READING, CHAMBER_SET_POINT = "imu/temperature_c", "chamber/reading_c", "chamber/set_point_c"
# each entity's series: name, colour (the chamber's set point purple, as the limits), width
TEMPERATURES = {IMU: ("IMU", (230, 85, 13), 2.0), CHAMBER_READING: ("chamber", (55, 126, 184), 1.5),
                CHAMBER_SET_POINT: ("chamber set point", (130, 0, 170), 1.0)}  # fmt: skip


class TemperatureLog:
    """When each temperature is due and at what trial time (called from the caller's thread); :meth:`write`
    (from the logging thread) logs a row."""

    def __init__(self) -> None:
        self.t_progress = 0.0  # the trial time of the pipeline's latest progress
        self._next_t = 0.0
        self._styled: set[str] = set()

    def imu_due(self, t: float, imu_c: float | None) -> bool:
        """A progress at trial time t with the IMU's latest temperature: whether to log it (the first progress of
        each ``PERIOD_S`` that has one)."""
        self.t_progress = max(self.t_progress, t)
        if imu_c is None or t < self._next_t:
            return False
        self._next_t = (np.floor(t / PERIOD_S) + 1.0) * PERIOD_S
        return True

    def write(self, rec, scalars: Callable[[str, np.ndarray, np.ndarray], None], path: str, t: float,
              value: float) -> None:
        """One row of ``path`` at trial time t through ``scalars``, its style logged to ``rec`` with its first."""
        if path not in self._styled:
            self._styled.add(path)
            name, color, width = TEMPERATURES[path]
            rec.log(path, rr.SeriesLines(names=name, colors=color, widths=width), static=True)
        scalars(path, np.array([t]), np.array([[value]]))
