"""Turntable control during a trial: arm the configured motion through the controller interface, check it,
always stop.

:class:`TableControl` opens ``turntable.controller`` (:data:`drivers.registry.TABLE_CONTROLLERS`), loads the limits, checks
the interlocks, commands ``turntable.motion`` (swing: synthesis mode, an oscillator about the centre
position; static: position; rate: rate) and turns the sync output on where the controller has a command
for it. :func:`refusal` says, before anything moves, why a controller cannot run a trial. :class:`MotionCheck` then watches the gimbal angles the table reports: after one
period of settling, each swinging axis must cover 80-120 % of its commanded peak-to-peak range over
the last period, a static axis must hold its position within 0.5 deg, a rate axis must turn within
10 % of its rate. ``stop`` turns every axis Off whatever happened, and keeps the error if that cannot
be confirmed.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from drivers.controllers import controller_options, make_controller
from drivers.registry import TABLE_CONTROLLERS
from drivers.table_controller import MOTION_MODES, TableError
from hil.config import TurntableConfig
from hil.pipeline.progress import Progress
from hil.samples import GIMBAL_AXES
from hil.units import DEG
from hil.vocabulary import TableMode

SETTLE_S = 2.0  # beyond the longest period, for the table to reach the commanded motion
STATIC_TOLERANCE_DEG = 0.5
RANGE_TOLERANCE = 0.2  # swing: peak-to-peak within +-20 % of the commanded
RATE_TOLERANCE = 0.1


def motion_needs(table: TurntableConfig) -> tuple[set[str], set[str]]:
    """The modes ``turntable.motion`` commands, and the gimbals it moves off their zero (a table that
    commands fewer axes leaves the others where they are)."""
    motion, modes, gimbals = table.motion, set(), set()
    for gimbal in GIMBAL_AXES:
        mode = _mode(table, gimbal)
        axis = getattr(motion.axes, gimbal)
        moves = (axis.amplitude_deg if mode == TableMode.SYNTHESIS else axis.rate_dps if mode == TableMode.RATE
                 else axis.center_deg)
        modes |= {mode} | ({TableMode.POSITION} if mode == TableMode.SYNTHESIS else set())
        gimbals |= {gimbal} if moves else set()
    return modes, gimbals


def check_controller(table: TurntableConfig, modes: set[str], gimbals: set[str]) -> None:
    """Raise :class:`TableError` (one line) when ``turntable.controller`` cannot move ``gimbals`` in ``modes``,
    nothing is sent."""
    options = controller_options(table)
    why = TABLE_CONTROLLERS.get(table.controller).refusal(modes, gimbals, options)
    if why is not None:
        raise TableError(f"{why}; nothing was sent")


def _mode(table: TurntableConfig, gimbal: str) -> TableMode:
    kind, axis = table.motion.kind, getattr(table.motion.axes, gimbal)
    return MOTION_MODES[kind] if kind != "swing" or axis.amplitude_deg else TableMode.POSITION


class TableControl:
    """The controller side of a trial; use as a context manager so the table is always turned off."""

    def __init__(self, url: str, table: TurntableConfig) -> None:
        if table.motion.kind == "positions":
            raise TableError("turntable.motion: kind 'positions' is not commanded by the harness; "
                             "run the sequence from the table's console or use swing, static or rate")
        self.table = table
        self.client = make_controller(table, url)
        self.stop_error: str | None = None

    def open(self) -> TableControl:
        """Open the command port; raises :class:`TableError`."""
        self.client.open()
        return self

    def __enter__(self) -> TableControl:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def arm(self) -> None:
        """Limits, interlock check, the configured motion on every axis the controller commands, sync output on."""
        client, motion = self.client, self.table.motion
        client.apply_limits()
        for gimbal in client.gimbals:
            axis, mode = getattr(motion.axes, gimbal), _mode(self.table, gimbal)
            if mode != TableMode.RATE:
                client.demand_position(gimbal, axis.center_deg)
            if mode == TableMode.SYNTHESIS:  # loaded before the mode starts it (TM-8004 4.7.6)
                client.demand_oscillator(gimbal, axis.amplitude_deg, 1.0 / axis.period_s, axis.phase_deg)
            client.set_mode(gimbal, mode)
            if mode == TableMode.RATE:
                client.demand_rate(gimbal, axis.rate_dps)
        client.sync_output(True)

    def stop(self) -> None:
        """Every axis Off and the port closed (safe to call twice); a failure is kept in :attr:`stop_error`."""
        try:
            self.client.close()
        except TableError as exc:
            self.stop_error = str(exc)


class MotionCheck:
    """Compares the reported gimbal angles with the commanded motion; :attr:`failure` says what is wrong.

    The angles come interpolated at every IMU instant; one per period of the table's ``rate_hz`` is kept.
    """

    def __init__(self, table: TurntableConfig, rate_hz: float) -> None:
        motion = table.motion
        self.kind = motion.kind
        self.axes = [getattr(motion.axes, g) for g in GIMBAL_AXES]
        periods = [a.period_s for a in self.axes if a.period_s and a.amplitude_deg]
        self.window = max(periods, default=2.0)
        self.settle = self.window + SETTLE_S
        self.rate_hz = rate_hz
        self._samples: deque[tuple[float, np.ndarray]] = deque(maxlen=int(self.window * rate_hz) + 1)
        self._tick: int | None = None  # table period of the last sample kept
        self._start: float | None = None
        self.checked_at: float | None = None
        self.failure: str | None = None

    def on_progress(self, progress: Progress) -> None:
        """A listener of the pipeline: the angles of the blocks the estimator took."""
        for block in progress.taken:
            if len(block.table_t):
                self.add(block.table_t, block.table_angles)

    def add(self, t: np.ndarray, angles: np.ndarray) -> None:
        """Gimbal angles (N, 3) rad at trial times t (N,) s."""
        for ti, a in zip(t.tolist(), angles):
            tick = math.floor(ti * self.rate_hz + 1e-9)  # an instant on a tick belongs to it
            if tick == self._tick:
                continue
            if self._start is None:
                self._start = ti
            self._tick = tick
            self._samples.append((ti, a))
        if self._samples and self._samples[-1][0] - self._start >= self.settle:
            t = self._samples[-1][0]
            if self.failure is None and (self.checked_at is None or t - self.checked_at >= self.window):
                self.failure = self._check()
                self.checked_at = t

    def _check(self) -> str | None:
        times = np.array([t for t, _ in self._samples])
        angles = np.unwrap(np.array([a for _, a in self._samples]), axis=0) / DEG
        for k, (gimbal, axis) in enumerate(zip(GIMBAL_AXES, self.axes)):
            if self.kind == "rate":
                rate = (angles[-1, k] - angles[0, k]) / (times[-1] - times[0])
                if abs(rate - axis.rate_dps) > RATE_TOLERANCE * max(abs(axis.rate_dps), 1.0):
                    return f"the {gimbal} axis turns at {rate:.2f} deg/s, commanded {axis.rate_dps:g}"
            elif self.kind == "swing" and axis.amplitude_deg:
                span = np.ptp(angles[:, k])
                wanted = 2.0 * axis.amplitude_deg
                if abs(span - wanted) > RANGE_TOLERANCE * wanted:
                    return f"the {gimbal} axis swings over {span:.2f} deg, commanded {wanted:g} deg peak to peak"
            else:
                offset = np.max(np.abs(_wrap_deg(angles[:, k] - axis.center_deg)))
                if offset > STATIC_TOLERANCE_DEG:
                    return f"the {gimbal} axis is {offset:.2f} deg away from its commanded {axis.center_deg:g} deg"
        return None


def _wrap_deg(x: np.ndarray) -> np.ndarray:
    return (x + 180.0) % 360.0 - 180.0

