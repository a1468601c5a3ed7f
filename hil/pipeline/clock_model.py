"""Affine clock model for a device without a sync input: its counter mapped to host time.

A free-running device counts on its own clock, so its count says when it latched only through
``host_time ~ offset + period * count``. Host receive times are late by a latency that is never
negative and sometimes large (scheduling, USB polling), so the fit follows the lower envelope: each
``bucket`` of counts contributes its earliest-arriving sample (the one least delayed) and the line is
fitted by least squares to the last ``buckets`` of those minima, then shifted down to run under all of
them. The latency floor that remains (the transport's fixed delay) is common to both streams of a
trial when they use the same kind of port, and cancels in the alignment.
"""

from __future__ import annotations

from collections import deque

import numpy as np


class AffineClock:
    """``time(count)`` in host seconds from ``(count, host_time)`` pairs fed in arrival order."""

    def __init__(self, nominal_rate_hz: float, bucket_s: float = 1.0, buckets: int = 120) -> None:
        self.nominal_period = 1.0 / nominal_rate_hz
        self.bucket = max(1, int(round(bucket_s * nominal_rate_hz)))
        self._minima: deque[tuple[int, float]] = deque(maxlen=buckets)
        self._current: tuple[int, float] | None = None  # the earliest arrival in the open bucket
        self._current_lead = 0.0
        self._bucket_id: int | None = None
        self._fit: tuple[float, float] | None = None  # (offset at count 0, period)

    def add(self, count: int, host_time: float) -> None:
        bucket = count // self.bucket
        if bucket != self._bucket_id:
            if self._current is not None:
                self._minima.append(self._current)
                self._refit()
            self._bucket_id, self._current = bucket, None
        lead = host_time - count * self.nominal_period  # arrival against the nominal clock
        if self._current is None or lead < self._current_lead:
            self._current, self._current_lead = (count, host_time), lead
        if self._fit is None:
            self._fit = (host_time - count * self.nominal_period, self.nominal_period)

    @property
    def ready(self) -> bool:
        return self._fit is not None

    @property
    def period(self) -> float:
        return self._fit[1] if self._fit else self.nominal_period

    def time(self, count: float) -> float:
        """Host time of ``count`` (s); the first sample's time until a fit exists."""
        offset, period = self._fit
        return offset + period * count

    def _refit(self) -> None:
        if len(self._minima) < 2:
            first = self._minima[0]
            self._fit = (first[1] - first[0] * self.nominal_period, self.nominal_period)
            return
        counts = np.array([c for c, _ in self._minima], dtype=float)
        times = np.array([t for _, t in self._minima])
        c0 = counts[0]
        slope, intercept = np.polyfit(counts - c0, times, 1)
        below = np.min(times - (intercept + slope * (counts - c0)))  # run under every minimum
        self._fit = (intercept + below - slope * c0, slope)
