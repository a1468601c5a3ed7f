"""The IMU's temperature as its frames report it (NaN where they carry none): result.json's
``streams.imu_temperature_c`` (mean, min and max over the trial's samples) and series.csv's ``temperature_c``
(per solution, the mean of the samples decoded since the solution before, else the one before's: a read may
bring several solutions). The estimator never sees it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import MappingProxyType

import numpy as np


class TemperatureTrack:
    """Takes each read's temperatures (:meth:`add`) and each step's new solutions (:meth:`solved`)."""

    def __init__(self) -> None:
        self._sum, self._n = 0.0, 0
        self._low, self._high = math.inf, -math.inf
        self._since = (0.0, 0)  # sum and count of the temperatures since the last solution
        self._last = math.nan  # the last solution's
        self._at: dict[float, float] = {}  # solution time (s) -> deg C
        self.latest: float | None = None  # the mean temperature of the last read that reported one

    def add(self, temperature_c: np.ndarray | None) -> None:
        """One read's samples' temperatures (deg C, NaN or None: none)."""
        if temperature_c is None:
            return
        known = temperature_c[np.isfinite(temperature_c)]
        if not len(known):
            return
        total = float(known.sum())
        self._sum, self._n = self._sum + total, self._n + len(known)
        self._low, self._high = min(self._low, float(known.min())), max(self._high, float(known.max()))
        self._since = (self._since[0] + total, self._since[1] + len(known))
        self.latest = total / len(known)

    def solved(self, times: Sequence[float]) -> None:
        """Solutions at trial times ``times`` (s): each has the mean temperature since the one before, else that
        one's."""
        if not len(times):
            return
        total, n = self._since
        self._last = total / n if n else self._last
        for t in times:
            self._at.setdefault(float(t), self._last)
        self._since = (0.0, 0)

    @property
    def at(self) -> MappingProxyType:
        """Each solution's temperature (deg C, NaN: none), by its trial time (s)."""
        return MappingProxyType(self._at)

    def summary(self) -> dict[str, float] | None:
        """``{"mean", "min", "max"}`` deg C over every sample that reported one; None when none did."""
        if not self._n:
            return None
        return {"mean": self._sum / self._n, "min": self._low, "max": self._high}
