"""The calibration schedule commanded live through the controller interface, its windows cut from the table's
reported angles.

:class:`CalibrationSequence` listens to the pipeline (:meth:`~CalibrationSequence.on_progress`) and follows
the angles the table reports (trial times and angles of each block the estimator took) step by step: it
commands a step's position on every axis, waits until the table reports it there and still (``ARRIVED_S``), lets it settle (``calibration.settle_s``), then holds the
dwell window for ``dwell_s``. A plateau moves to its start the same way, then commands the rate and
waits until the reported rate holds it (``ARRIVED_S``), settles, and keeps the window for its
duration, or until the rate leaves the plateau (a middle axis braking at its position limit). Then
the next step. A table that moves during a dwell, or leaves its rate during a plateau's settling, is a
:attr:`failure`. Nothing here looks at the IMU's variance: the windows come from the table alone.

The increments the estimator took come with them and are kept; :meth:`windows` cuts the
calibration windows from them at the end: the encoder angles of each IMU interval are its midpoint's,
the mean of the readings at its two ends (across the +-180 deg seam), and a plateau's rate is the
encoder's turn over the window's intervals divided by their length.

For the live views: ``on_step(t, index)`` is called when a step is commanded (trial time t: the end of the
previous step's window, 0 for the first), ``on_window(t, index, window)`` once a closed window's
samples have all arrived (t its end; the window as :meth:`windows` will cut it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hil.estimation.calibration_model import Window, window_from_samples
from hil.estimation.calibration_schedule import Dwell, Plateau, Schedule
from hil.frames import wrapped
from hil.pipeline.progress import Progress
from hil.samples import GIMBAL_AXES
from hil.units import DEG
from hil.vocabulary import CalibrationPhase

POSITION_TOLERANCE = 0.05 * DEG  # arrived: within this of the demand (encoder zero errors are far smaller)
STILL_RATE = 0.01 * DEG  # rad/s: below this an axis is at rest (the encoder's 1e-6 deg over 5 ms is 2e-4 deg/s)
RATE_TOLERANCE = 1e-3  # relative: a plateau's reported rate within this of the demand (+ STILL_RATE)
ARRIVED_S = 0.2  # at the demand and still (or at the rate) for this long before the settle time starts
BRAKE_MARGIN_S = 0.05  # a plateau that leaves its rate ends this long before the first reading off it


@dataclass
class StepWindow:
    """One step's window in trial time (s), as cut from the reported angles."""

    step: Dwell | Plateau
    start: float
    end: float


class CalibrationSequence:
    """Commands the schedule through ``client`` (a :class:`drivers.table_controller.TableController`) and
    finds each step's window; :attr:`done` once every step has its window, :attr:`failure` says what
    went wrong. ``sample_period`` is the IMU's interval (s); ``on_step`` and ``on_window`` as in the module
    docstring."""

    def __init__(self, schedule: Schedule, client, sample_period: float,
                 on_step: Callable[[float, int], None] | None = None,
                 on_window: Callable[[float, int, Window], None] | None = None, lacking_max: float = 0.0) -> None:
        self.steps: list[Dwell | Plateau] = list(schedule.dwells) + list(schedule.plateaus)
        self.client = client
        self.period = sample_period
        self.lacking_max = lacking_max  # fraction of a window's samples that may be missing (rejected, lost)
        self.on_step = on_step
        self.on_window = on_window
        self._reported = 0  # windows handed to on_window
        self.windows_found: list[StepWindow] = []
        self.failure: str | None = None
        self._index = -1
        self._phase = CalibrationPhase.IDLE
        self._since: float | None = None  # when the current condition started to hold
        self._window_start = 0.0
        self._last: tuple[float, np.ndarray] | None = None
        self._samples: list[tuple[np.ndarray, ...]] = []

    @property
    def done(self) -> bool:
        return self._index >= len(self.steps)

    @property
    def progress(self) -> str:
        """Which step the table is on, for the console."""
        if self.done:
            return f"all {len(self.steps)} steps done"
        return f"step {self._index + 1} of {len(self.steps)}: {self._phase}"

    def start(self) -> None:
        """Command the first step."""
        self._next(0.0)

    def on_progress(self, progress: Progress) -> None:
        """A listener of the pipeline: each block the estimator took, its samples (:meth:`keep`) then its table
        angles (:meth:`add`)."""
        for block in progress.taken:
            for run in block.samples:
                self.keep(run.t, run.dtheta, run.dv, run.angles)
            if len(block.table_t):
                self.add(block.table_t, block.table_angles)

    def keep(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, angles: np.ndarray) -> None:
        """Aligned samples the estimator took, kept for :meth:`windows`;
        a closed window whose samples have all arrived is cut at once: one that lacks samples ends the trial
        (:attr:`failure`), the others go to ``on_window``."""
        self._samples.append((t, dtheta, dv, angles))
        if self._reported < len(self.windows_found) and len(t) and t[-1] >= self.windows_found[self._reported].end:
            self._report(float(t[-1]))

    def report_rest(self) -> None:
        """End of data: the closed windows not handed to ``on_window`` yet (the data ended at or before a window's
        end), cut from the samples that came; one that lacks samples is left for the fit to judge."""
        if self._samples:
            self._report(math.inf, judge=False)

    def _report(self, until: float, judge: bool = True) -> None:
        """Cut the closed windows that end by ``until`` and hand them to ``on_window``; a window that lacks samples
        ends the trial (:attr:`failure`) when ``judge``."""
        samples = self._joined()
        while self._reported < len(self.windows_found) and until >= self.windows_found[self._reported].end:
            try:
                window = self._cut(self._reported, *samples)
            except ValueError as exc:
                self.failure = self.failure or (str(exc) if judge else None)
                return
            if self.on_window is not None:
                self.on_window(self.windows_found[self._reported].end, self._reported, window)
            self._reported += 1

    def add(self, t: np.ndarray, angles: np.ndarray) -> None:
        """Reported gimbal angles (N, 3) rad at trial times t (N,) s: advance through the schedule."""
        if self._last is not None:
            t, angles = np.concatenate(([self._last[0]], t)), np.vstack(([self._last[1]], angles))
        if len(t) == 0:
            return
        self._last = (float(t[-1]), angles[-1])
        dt = np.diff(t)
        rates = wrapped(np.diff(angles, axis=0)) / np.where(dt > 0, dt, np.inf)[:, None]
        times, angles = t[1:].tolist(), angles[1:]
        still = np.all(np.abs(rates) < STILL_RATE, axis=1)
        i = 0
        while i < len(times) and not self.done and self.failure is None:
            index = self._index
            step = self.steps[index]
            wanted = np.zeros(3)
            if isinstance(step, Plateau):
                wanted[step.axis] = step.rate
                limit = STILL_RATE + RATE_TOLERANCE * abs(step.rate)
            at_rate = still if not isinstance(step, Plateau) else np.all(np.abs(rates - wanted) < limit, axis=1)
            there = np.all(np.abs(wrapped(angles - np.array(step.angles))) < POSITION_TOLERANCE, axis=1) & still
            while i < len(times) and self._index == index and self.failure is None:
                if dt[i] > 0:
                    self._advance(times[i], bool(there[i]), bool(at_rate[i]), rates[i])
                i += 1

    def _advance(self, t: float, there: bool, at_rate: bool, rates: np.ndarray) -> None:
        """One reading: ``there`` at the step's angles and still, ``at_rate`` on the step's rates (a dwell's:
        still)."""
        step = self.steps[self._index]
        plateau = isinstance(step, Plateau)
        if self._phase in (CalibrationPhase.MOVING, CalibrationPhase.RAMPING):
            if not (there if self._phase == CalibrationPhase.MOVING else at_rate):
                self._since = None
                return
            self._since = t if self._since is None else self._since
            if t - self._since < ARRIVED_S:
                return
            if self._phase == CalibrationPhase.MOVING and plateau:
                gimbal = GIMBAL_AXES[step.axis]
                self.client.set_mode(gimbal, "rate")
                self.client.demand_rate(gimbal, step.rate / DEG)
                self._phase, self._since = CalibrationPhase.RAMPING, None
                return
            self._phase, self._window_start = CalibrationPhase.WINDOW, t + step.settle_s
            return
        length = step.duration_s if plateau else step.dwell_s
        if t < self._window_start:
            if not at_rate:
                self.failure = (f"calibration {self._name()}: the table moved while settling "
                                f"(rates {np.round(rates / DEG, 4).tolist()} deg/s)")
            return
        if not at_rate:
            if not plateau:
                self.failure = f"calibration {self._name()}: the table moved during the dwell"
                return
            self._close(t - BRAKE_MARGIN_S)
        elif t >= self._window_start + length - 1e-9:
            self._close(self._window_start + length)  # the nominal end, whatever gap in the readings came before t

    def _close(self, end: float) -> None:
        step = self.steps[self._index]
        if end - self._window_start < self.period:
            self.failure = f"calibration {self._name()}: the window is empty"
            return
        self.windows_found.append(StepWindow(step, self._window_start, end))
        self._next(end)

    def _next(self, t: float) -> None:
        self._index += 1
        self._phase, self._since = CalibrationPhase.MOVING, None
        if self.done:
            return
        step = self.steps[self._index]
        for k, gimbal in enumerate(GIMBAL_AXES):
            if gimbal in self.client.gimbals:
                self.client.demand_position(gimbal, step.angles[k] / DEG)
                self.client.set_mode(gimbal, "position")
        if self.on_step is not None:
            self.on_step(t, self._index)

    def _name(self, index: int | None = None) -> str:
        """The step's name (the current one's without ``index``), as the messages give it."""
        index = self._index if index is None else index
        if isinstance(self.steps[index], Plateau):
            return f"plateau {index - sum(isinstance(s, Dwell) for s in self.steps) + 1}"
        return f"position {index + 1}"

    def windows(self) -> list[Window]:
        """The calibration windows (dwells, then plateaus) from the samples kept, each the samples whose
        intervals lie inside the window and follow their predecessor without a gap."""
        if not self._samples:
            return []
        samples = self._joined()
        return [self._cut(index, *samples) for index in range(len(self.windows_found))]

    def _joined(self) -> tuple[np.ndarray, ...]:
        """The samples kept as (t, dtheta, dv, angles, contiguous): contiguous marks a sample that follows
        its predecessor one period later, both with angles."""
        t, dtheta, dv, angles = (np.concatenate(parts) for parts in zip(*self._samples))
        contiguous = np.concatenate(([False], np.abs(np.diff(t) - self.period) < 0.25 * self.period))
        contiguous &= np.all(np.isfinite(angles), axis=1) & np.concatenate(([False], np.all(np.isfinite(angles[:-1]),
                                                                                             axis=1)))
        return t, dtheta, dv, angles, contiguous

    def _cut(self, index: int, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, angles: np.ndarray,
             contiguous: np.ndarray) -> Window:
        """The window of step ``index`` (its window is ``windows_found[index]``) from the samples kept."""
        found = self.windows_found[index]
        sel = np.flatnonzero(contiguous & (t - self.period >= found.start - 1e-9) & (t <= found.end + 1e-9))
        expected = round((found.end - found.start) / self.period)
        if expected - len(sel) > max(1.0, self.lacking_max * expected):
            raise ValueError(f"calibration {self._name(index)}: {expected - len(sel)} of the "
                             f"{expected} samples of its window {found.start:.2f}..{found.end:.2f} s were rejected or "
                             f"lost (more than {self.lacking_max:.2%}): no fit on it")
        turn = wrapped(angles[sel] - angles[sel - 1])  # each interval's encoder turn
        rates = np.zeros(3)
        if isinstance(found.step, Plateau):
            axis = found.step.axis
            rates[axis] = np.sum(turn[:, axis]) / (len(sel) * self.period)
        mid = angles[sel] - 0.5 * turn
        dt = np.full(len(sel), self.period)
        return window_from_samples(dtheta[sel], dv[sel], dt, mid, rates)
