"""Time offset between the IMU and the table streams, from the gyro against the table's angular rate.

A check on the sync alignment: if both streams are placed correctly in time, the body rate the gyros
measure and the body rate the interpolated gimbal angles imply line up. The offset is found by
cross-correlation (whole samples) and refined by Gauss-Newton on the cubic spline of the table's
rate, ``omega_gyro(t) = omega_table(t + d)``.
A positive offset means the table's angles lag the IMU (they show an instant that much earlier than
the one they are placed at: a latch delay configured too short by it). The earth rate is added to
the table's body rate; the gyros' constant difference from it is estimated alongside, per body axis: their
rate error against the table (:meth:`TimeOffsetEstimator.gyro_rate_error`, the gyro bias, plus the scale
factor and misalignment times the rate of an axis the table turns at a steady rate).
"""

from __future__ import annotations

import threading

import numpy as np

from hil.frames import Earth, TableGeometry

WINDOW_S = 60.0  # a continuous stretch contributes its last minute
MIN_WINDOW_S = 4.0  # shorter stretches (between IMU gaps) are not used
MAX_LAG = 20  # samples searched either side by the cross-correlation
NEWTON_STEPS = 4
ONE_WINDOW_AT_A_TIME = threading.Lock()  # every estimator of the process: :meth:`TimeOffsetEstimator._window_fit`


class TimeOffsetEstimator:
    """Keeps the last ``WINDOW_S`` of gyro increments and table angles; :meth:`estimate` gives the offset (s),
    :meth:`gyro_rate_error` the gyros' rate error against the table (rad/s)."""

    def __init__(self, earth: Earth, geometry: TableGeometry, rate_hz: float) -> None:
        self.earth = earth
        self.geometry = geometry
        self.rate_hz = rate_hz
        self._rows = np.empty((int(WINDOW_S * rate_hz), 7))  # a ring of [t, dtheta (3), angles (3)]
        self._count = 0  # rows held, the newest ending at ``_next``
        self._next = 0
        self._added = 0  # rows ever added: with ``_count``, what the window's fit was taken of
        self._fitted: tuple[tuple[int, int], np.ndarray | None] | None = None
        self._done: list[tuple[np.ndarray, int]] = []  # ([offset s, rate errors rad/s], samples) of finished windows

    def add(self, t: np.ndarray, dtheta: np.ndarray, angles: np.ndarray) -> None:
        """Consecutive aligned samples: times (N,), gyro increments and angles (N, 3); a sample without
        angles (NaN) is a discontinuity."""
        missing = np.flatnonzero(np.isnan(angles[:, 0]))
        start = 0
        for stop in [*missing.tolist(), len(t)]:
            self._keep(np.column_stack((t[start:stop], dtheta[start:stop], angles[start:stop])))
            if stop < len(t):
                self.restart()
            start = stop + 1

    def _keep(self, rows: np.ndarray) -> None:
        """Append rows to the ring, the oldest overwritten beyond its size."""
        size = len(self._rows)
        rows = rows[-size:]
        at = (self._next + np.arange(len(rows))) % size
        self._rows[at] = rows
        self._next = (self._next + len(rows)) % size
        self._added += len(rows)
        self._count = min(self._count + len(rows), size)

    def _window(self) -> np.ndarray:
        """The rows held, oldest first."""
        return self._rows[(self._next - self._count + np.arange(self._count)) % len(self._rows)]

    def restart(self) -> None:
        """A discontinuity (gap): keep the estimate of the window so far, and start a new one."""
        fit = self._window_fit()
        if fit is not None:
            self._done.append((fit, self._count))
        self._count = self._next = 0

    def estimate(self) -> float | None:
        """The lag of the table behind the IMU (s): the sample-weighted mean over the continuous windows
        of at least ``MIN_WINDOW_S`` of moving data (the last ``WINDOW_S`` of each); None without one."""
        fit = self._fit()
        return None if fit is None else float(fit[0])

    def gyro_rate_error(self) -> np.ndarray | None:
        """The gyros' rate minus the table's (earth rate included) per body axis (3,) rad/s, a constant per
        window weighted as :meth:`estimate`; None without a window."""
        fit = self._fit()
        return None if fit is None else fit[1:]

    def _fit(self) -> np.ndarray | None:
        """[offset s, rate error x, y, z rad/s], the windows' sample-weighted mean; None without one."""
        results = list(self._done)
        fit = self._window_fit()
        if fit is not None:
            results.append((fit, self._count))
        if not results:
            return None
        return np.average([r for r, _ in results], axis=0, weights=[n for _, n in results])

    def _window_fit(self) -> np.ndarray | None:
        """:meth:`_window_estimate`, taken once for the rows held. The pipelines of several units in one process
        take theirs one at a time: each holds some 50 MB while it runs at 1 kHz, which would otherwise add up."""
        key = (self._added, self._count)
        if self._fitted is None or self._fitted[0] != key:
            with ONE_WINDOW_AT_A_TIME:
                self._fitted = key, self._window_estimate()
        return self._fitted[1]

    def _window_estimate(self) -> np.ndarray | None:
        """[offset s, rate error x, y, z rad/s] of the current window; None when it is too short or still."""
        from scipy.interpolate import CubicSpline  # here, not with the module: 0.2 s of every trial's start-up

        if self._count < MIN_WINDOW_S * self.rate_hz:
            return None
        rows = self._window()
        t = rows[:, 0]
        dt = np.diff(t)
        gyro = rows[1:, 1:4] / dt[:, None]  # mean rate over each interval
        angles = np.unwrap(rows[:, 4:7], axis=0)
        # the table's body rate over the same intervals (angle chord) plus the earth rate seen in the body
        mid = 0.5 * (angles[1:] + angles[:-1])
        c_bn, middle_inner, inner = self.geometry.attitude_matrix(mid)
        table = self.geometry.body_rate_from(middle_inner, inner, np.diff(angles, axis=0) / dt[:, None])
        table += np.einsum("nji,j->ni", c_bn, self.earth.omega_n)
        if np.sum((table - table.mean(axis=0)) ** 2) < 1e-12:
            return None  # the table is not moving
        lags = np.arange(-MAX_LAG, MAX_LAG + 1)
        m = len(gyro) - 2 * MAX_LAG
        g = gyro[MAX_LAG : MAX_LAG + m]
        centred = table - table.mean(axis=0)
        g_centred = g - g.mean(axis=0)
        score = [np.sum(g_centred * centred[MAX_LAG + k : MAX_LAG + k + m]) for k in lags]
        shift = float(lags[int(np.argmax(score))])
        spline = CubicSpline(np.arange(len(table)), table)
        at = np.arange(MAX_LAG, MAX_LAG + m, dtype=float)
        design = np.empty((3 * m, 4))  # [d r / d shift, a constant per axis: the gyros' rate error]
        design[:, 1:] = np.tile(np.eye(3), (m, 1))
        for _ in range(NEWTON_STEPS):  # Gauss-Newton on the sub-sample shift and the constant offsets
            r, r_dot = spline(at + shift), spline(at + shift, 1)
            design[:, 0] = r_dot.ravel()
            step, *_ = np.linalg.lstsq(design, (g - r).ravel(), rcond=None)
            shift += step[0]
        return np.concatenate(([shift / self.rate_hz], step[1:]))
