"""The rate-table tests' steps, commanded through the controller interface, their windows cut from the table's
reported angles (docs/ratetests.md).

A step places one gyro axis on the turning gimbal (a three-axis table: the middle and inner gimbals put it
up, on the outer axis; a single-axis table: the gyro its axis lies along) and then turns that gimbal at a rate
or oscillates it. :class:`RateSequence` follows the reported angles sample by sample: it commands the
placement, waits until the table is there and still (``ARRIVED_S``), commands the motion, waits until the
table is at the rate for ``ARRIVED_S`` (an oscillation: until it has started), lets it settle and keeps the
window: the whole turns (cycles) of the step's length. Nothing here looks at the IMU: the windows come from
the table alone, whose angles at every sample aligned advance the steps, those the IMU flagged invalid (a gyro
clipping at its range) too. :meth:`RateSequence.windows` cuts them from the samples kept (the pipeline's good
ones): each IMU interval's gyro increment and encoder turn (the difference of the readings at its two ends,
across the +-180 deg seam).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.estimation.calibration_schedule import AXIS_UP_DOWN
from hil.frames import TableGeometry, wrapped
from hil.samples import GIMBAL_AXES
from hil.units import DEG

POSITION_TOLERANCE = 0.05 * DEG
STILL_RATE = 0.01 * DEG  # rad/s
RATE_TOLERANCE = 1e-3  # relative, plus STILL_RATE
ARRIVED_S = 0.2
GYRO_AXES = "xyz"


@dataclass(frozen=True)
class RateStep:
    """Place ``angles`` (rad, (outer, middle, inner)), then turn gimbal ``axis`` at ``rate`` (rad/s) or oscillate
    it by ``amplitude`` (rad) at ``frequency`` (Hz); the window ``window_s`` long starts ``settle_s`` after."""

    gyro: int
    angles: tuple[float, float, float]
    axis: int
    window_s: float
    settle_s: float
    rate: float = 0.0
    amplitude: float = 0.0
    frequency: float = 0.0

    @property
    def name(self) -> str:
        what = f"{self.rate / DEG:g} deg/s" if self.frequency == 0.0 else f"{self.frequency:g} Hz"
        return f"gyro {GYRO_AXES[self.gyro]} at {what}"


@dataclass(frozen=True)
class StepWindow:
    """A step's samples: times (s), the gyro's increments (N, 3), and the encoder's turn (N, 3) and time (N,)
    since the sample before (one period, or the gap the pipeline left where it took samples out)."""

    step: RateStep
    t: np.ndarray
    dtheta: np.ndarray
    turn: np.ndarray
    dt: np.ndarray


def placements(gimbals: tuple[str, ...], geometry: TableGeometry, axes: list[str], key: str
               ) -> list[tuple[int, tuple[float, float, float], int]]:
    """(gyro, angles, turning gimbal) for each gyro axis of ``axes`` the table can put on a rate axis; a
    single-axis table keeps its one gimbal at zero and tests the gyro it lies along. ValueError (naming ``key``)
    when none of ``axes`` can be."""
    if {"middle", "inner"} <= set(gimbals):
        return [(GYRO_AXES.index(a), (0.0, *AXIS_UP_DOWN[2 * GYRO_AXES.index(a)]), 0) for a in axes]
    axis = GIMBAL_AXES.index(gimbals[0])
    gyro = int(np.argmax(np.abs(axis_in_body(geometry, (0.0, 0.0, 0.0), axis))))
    if GYRO_AXES[gyro] not in axes:
        raise ValueError(f"{key}: the table turns its {gimbals[0]} axis only, which lies along gyro "
                         f"{GYRO_AXES[gyro]}, not among {axes}")
    return [(gyro, (0.0, 0.0, 0.0), axis)]


def _since(before: tuple[float, np.ndarray], t: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's encoder turn (N, 3) and time (N,) since the one before (``before``: the last of the previous
    call), across the +-180 deg seam."""
    turn = wrapped(np.diff(np.vstack([before[1], angles]), axis=0))
    return turn, np.diff(np.concatenate([[before[0]], t]))


def axis_in_body(geometry: TableGeometry, angles: tuple[float, float, float], axis: int) -> np.ndarray:
    """The unit vector of gimbal ``axis`` in the body frame at ``angles`` (the same whatever that gimbal's angle)."""
    _, middle_inner, inner = geometry.attitude_matrix(np.array(angles))
    return geometry.body_rate_from(middle_inner, inner, np.eye(3)[axis][None, :])[0]


class RateSequence:
    """Commands ``steps`` through ``client`` (a :class:`drivers.table_controller.TableController`) and finds each
    step's window; :attr:`done` once every step has one, :attr:`failure` says what went wrong."""

    def __init__(self, steps: list[RateStep], client, sample_period: float) -> None:
        self.steps = steps
        self.client = client
        self.period = sample_period
        self.failure: str | None = None
        self.found: list[tuple[float, float]] = []  # each step's window (start, end), trial time
        self._index = -1
        self._phase = ""
        self._since: float | None = None
        self._window_start = 0.0
        self._last: tuple[float, np.ndarray] | None = None  # the last sample kept: (t, angles)
        self._table: tuple[float, np.ndarray] | None = None  # the last table reading the steps advanced on
        self._kept: list[tuple[np.ndarray, ...]] = []

    @property
    def done(self) -> bool:
        return self._index >= len(self.steps)

    @property
    def progress(self) -> str:
        return f"all {len(self.steps)} steps done" if self.done else \
            f"step {self._index + 1} of {len(self.steps)} ({self.steps[self._index].name}): {self._phase}"

    def start(self) -> None:
        self._next()

    def on_progress(self, progress) -> None:
        """A listener of the pipeline (a :class:`~hil.pipeline.progress.Progress`): the samples it took are kept,
        and the steps advance on the table's angles of each block, the samples it did not take included."""
        for block in progress.taken:
            for run in block.samples:
                self._keep(run.t, run.dtheta, run.angles)
            self._advance_on(block.table_t, block.table_angles)

    def feed(self, t: np.ndarray, dtheta: np.ndarray, angles: np.ndarray) -> None:
        """Aligned samples (times (N,), gyro increments and encoder angles (N, 3)): kept, and the steps advanced."""
        self._keep(t, dtheta, angles)
        self._advance_on(t, angles)

    def _keep(self, t: np.ndarray, dtheta: np.ndarray, angles: np.ndarray) -> None:
        """Samples kept for the windows, each with the encoder's turn and time since the sample kept before."""
        if not len(t):
            return
        before = (t[0] - self.period, angles[0]) if self._last is None else self._last
        self._last = (float(t[-1]), angles[-1])
        self._kept.append((t, dtheta, *_since(before, t, angles)))

    def _advance_on(self, t: np.ndarray, angles: np.ndarray) -> None:
        """The steps advanced on the table's readings ``angles`` (N, 3) at ``t`` (N,)."""
        if not len(t):
            return
        before = (t[0] - self.period, angles[0]) if self._table is None else self._table
        self._table = (float(t[-1]), angles[-1])
        turn, dt = _since(before, t, angles)
        rates = turn / dt[:, None]
        for k in range(len(t)):
            if self.done or self.failure is not None:
                return
            self._advance(float(t[k]), angles[k], rates[k])

    def _advance(self, t: float, angles: np.ndarray, rates: np.ndarray) -> None:
        step = self.steps[self._index]
        still = bool(np.all(np.abs(rates) < STILL_RATE))
        if self._phase == "placing":
            off = np.abs(wrapped(angles - np.array(step.angles))) >= POSITION_TOLERANCE
            if step.rate:
                off[step.axis] = False  # a rate step's gimbal turns from wherever it stopped
            there = still and not off.any()
            if self._held(t, there):
                self._command(step)
        elif self._phase == "starting":
            if step.frequency:
                started = abs(rates[step.axis]) > 0.5 * step.amplitude * 2.0 * math.pi * step.frequency
                ready = started and self._held(t, True, 0.0)
            else:
                ready = self._held(t, abs(rates[step.axis] - step.rate) < STILL_RATE + RATE_TOLERANCE * abs(step.rate))
            if ready:
                self._phase, self._window_start = "window", t + step.settle_s
        elif t >= self._window_start + step.window_s - 1e-9:
            self.found.append((self._window_start, self._window_start + step.window_s))
            self._next()

    def _held(self, t: float, condition: bool, length: float = ARRIVED_S) -> bool:
        """Whether ``condition`` has held for ``length`` s up to t."""
        if not condition:
            self._since = None
            return False
        self._since = t if self._since is None else self._since
        return t - self._since >= length

    def _command(self, step: RateStep) -> None:
        gimbal = GIMBAL_AXES[step.axis]
        if step.frequency:
            self.client.demand_oscillator(gimbal, step.amplitude / DEG, step.frequency, 0.0)
            self.client.set_mode(gimbal, "synthesis")
        else:
            self.client.demand_rate(gimbal, step.rate / DEG)
        self._phase, self._since = "starting", None

    def _next(self) -> None:
        self._index += 1
        self._phase, self._since = "placing", None
        if self.done:
            return
        step = self.steps[self._index]
        for k, gimbal in enumerate(GIMBAL_AXES):
            if gimbal in self.client.gimbals and step.rate and k == step.axis:
                self.client.set_mode(gimbal, "rate")  # to rest where it is: a position would unwind its turns
                self.client.demand_rate(gimbal, 0.0)
            elif gimbal in self.client.gimbals:
                self.client.demand_position(gimbal, step.angles[k] / DEG)
                self.client.set_mode(gimbal, "position")

    def windows(self) -> list[StepWindow]:
        """Each found window's samples: the intervals inside it that have the encoder's turn."""
        t, dtheta, turn, dt = (np.concatenate(parts) for parts in zip(*self._kept))
        out = []
        for step, (start, end) in zip(self.steps, self.found):
            sel = (t - dt >= start - 1e-9) & (t <= end + 1e-9) & np.isfinite(turn).all(axis=1)
            out.append(StepWindow(step, t[sel], dtheta[sel], turn[sel], dt[sel]))
        return out
