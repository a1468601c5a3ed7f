"""A calibration's soak at one chamber set point (``calibration.soak``), judged on the IMU's own temperature.

The chamber is sent to the set point when the soak starts; every ``POLL_S`` of trial time its reading is taken
through its controller. Once the reading is within ``stable_within_c`` of the set point, the soak watches the
temperature the IMU reports in its frames (:attr:`hil.pipeline.progress.Progress.temperature_c`): it is over when
every reading of the last ``for_s`` lies within ``stable_within_c`` of the latest one. The chamber's air settles
long before the sensor inside the table does (the case's lag, the electronics' self-heating), so a soak on the
chamber's reading alone would calibrate a sensor still on its way.

It fails (:attr:`Soak.failure`) when ``timeout_s`` passes first, naming the temperatures seen, when the IMU reports
no temperature for ``for_s`` once the chamber is there, or at once when
the chamber's reading holds still (changes less than ``HELD_C`` over ``stalled_s``) while it is more than
``FAR_C`` from its set point: a heater or cooling fault, which waiting would not mend.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from hil.config_environment import SoakSettings

POLL_S = 1.0  # trial seconds between two readings of the chamber
HELD_C = 0.1  # deg C: a chamber reading that changes less than this over stalled_s holds still (the F4's 0.1 display)
FAR_C = 2.0  # deg C: ... while this far from its set point is a heater fault


class Soak:
    """The soak at ``set_point_c`` through ``chamber`` (a chamber controller), started at trial time ``t0``; fed
    each progress's trial time and IMU temperature (:meth:`update`) until :attr:`done` or :attr:`failure`."""

    def __init__(self, set_point_c: float, settings: SoakSettings, chamber, t0: float) -> None:
        self.set_point_c, self.settings, self.chamber, self.t0 = set_point_c, settings, chamber, t0
        self.chamber_readings: deque[tuple[float, float]] = deque()  # (t, deg C) over the last stalled_s
        self.imu: deque[tuple[float, float]] = deque()  # (t, deg C) over the last for_s
        self.reached_at: float | None = None  # when the chamber's reading came within stable_within_c
        self.done = False
        self.failure: str | None = None
        self.took_s = 0.0
        self._next_poll = t0
        self._chamber_call(lambda: chamber.set_set_point_c(set_point_c))

    @property
    def state(self) -> str:
        """What the soak waits for, for the console."""
        if self.reached_at is None:
            return f"soak at {self.set_point_c:g} deg C: the chamber at {self._chamber_c():.1f} deg C"
        return f"soak at {self.set_point_c:g} deg C: the IMU at {self._imu_c():.2f} deg C"

    def update(self, t: float, imu_c: float | None) -> None:
        """One progress: trial time ``t`` (s) and the IMU's latest temperature (deg C, None: none reported)."""
        if self.done or self.failure is not None:
            return
        if imu_c is not None and (not self.imu or t > self.imu[-1][0]):
            self.imu.append((t, imu_c))
            while self.imu[0][0] < t - self.settings.for_s:
                self.imu.popleft()
        if t < self._next_poll:
            return
        self._next_poll = t + POLL_S
        self._poll(t)

    def _poll(self, t: float) -> None:
        """Read the chamber and judge the soak at trial time ``t``."""
        s = self.settings
        reading = self._chamber_call(self.chamber.temperature_c)
        if reading is None:
            return
        self.chamber_readings.append((t, reading))
        while self.chamber_readings[0][0] < t - s.stalled_s:
            self.chamber_readings.popleft()
        if self.reached_at is None and abs(reading - self.set_point_c) <= s.stable_within_c:
            self.reached_at = t
        if self.reached_at is None:
            self._check_heater(t, reading)
        elif t - self.reached_at >= s.for_s and not self.imu:
            self.failure = (f"soak at {self.set_point_c:g} deg C: the IMU reported no temperature in the last "
                            f"{s.for_s:g} s (calibration.soak.for_s): a calibration over temperature needs an IMU "
                            "whose frames carry it")
        elif t - self.reached_at >= s.for_s and self._imu_steady(t):
            self.done, self.took_s = True, t - self.t0
            return
        if self.failure is None and t - self.t0 >= s.timeout_s:
            span = np.ptp([c for _, c in self.imu]) if self.imu else float("nan")
            self.failure = (f"soak at {self.set_point_c:g} deg C: not stable within {s.timeout_s:g} s "
                            f"(calibration.soak.timeout_s): the chamber at {reading:.1f} deg C, the IMU at "
                            f"{self._imu_c():.2f} deg C, moving over {span:.2f} deg C in the last {s.for_s:g} s "
                            f"(stable_within_c {s.stable_within_c:g})")

    def _chamber_call(self, request):
        """``request()`` to the chamber's controller; one that fails (the controller stopped answering) fails the
        soak naming ``environment.chamber`` (None)."""
        from drivers.watlow_f4 import ChamberError

        try:
            return request()
        except ChamberError as exc:
            self.failure = f"soak at {self.set_point_c:g} deg C: environment.chamber: {exc}"
            return None

    def _check_heater(self, t: float, reading: float) -> None:
        """Fail when the chamber's reading has held still for ``stalled_s`` while far from the set point."""
        s = self.settings
        first_t = self.chamber_readings[0][0]
        values = [c for _, c in self.chamber_readings]
        if t - self.t0 >= s.stalled_s and t - first_t >= s.stalled_s - POLL_S and np.ptp(values) < HELD_C \
                and abs(reading - self.set_point_c) > FAR_C:
            far = abs(reading - self.set_point_c)
            self.failure = (f"soak at {self.set_point_c:g} deg C: the chamber's reading held at {reading:.1f} deg C "
                            f"for {s.stalled_s:g} s (calibration.soak.stalled_s), {far:.1f} deg C from its set point: "
                            "a heater or cooling fault of environment.chamber")

    def _imu_steady(self, t: float) -> bool:
        """The IMU's readings cover the last ``for_s`` and lie within ``stable_within_c`` of the latest."""
        s = self.settings
        if not self.imu or self.imu[0][0] > t - s.for_s + POLL_S:
            return False
        values = np.array([c for _, c in self.imu])
        return bool(np.max(np.abs(values - values[-1])) <= s.stable_within_c)

    def _chamber_c(self) -> float:
        return self.chamber_readings[-1][1] if self.chamber_readings else float("nan")

    def _imu_c(self) -> float:
        return self.imu[-1][1] if self.imu else float("nan")

    def record(self) -> dict:
        """calibration.json's figures of a completed soak."""
        return {"set_point_c": self.set_point_c, "chamber_c": self._chamber_c(), "soak_s": self.took_s}
