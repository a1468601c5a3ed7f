"""Calibration schedules: dwell positions for the accelerometers, rate plateaus for the gyros.

The 18 positions are those of section 3 of the three-stage self-calibration paper (2018), derived for
our gimbals (outer z vertical, middle x, inner y; ``C_b^n = Rz(outer) Rx(middle) Ry(inner)``). With a
level table and the default mounting, gravity's direction in the body frame is

    u = Ry(inner)^T Rx(middle)^T e_up = (-sin(inner) cos(middle), sin(middle), cos(inner) cos(middle)),

independent of the outer angle. Six positions put each sensitive axis up and down along u; twelve put
one axis horizontal and the other two at 45 degrees to the vertical. Angles are in rad and ordered
(outer, middle, inner) as everywhere else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hil.config import CalibrationConfig, LimitsConfig
from hil.samples import GIMBAL_AXES
from hil.units import DEG

Q = math.pi / 4.0
MIDDLE_SWEEP = 150.0 * DEG  # the middle axis's rate window spans this much of its +-90 deg range

# (middle, inner) for each sensitive axis up and down: u = +-e_x, +-e_y, +-e_z.
AXIS_UP_DOWN = ((0.0, -2 * Q), (0.0, 2 * Q), (2 * Q, 0.0), (-2 * Q, 0.0), (0.0, 0.0), (0.0, 4 * Q))
# One axis horizontal, the other two at 45 deg: x horizontal (u_x = 0), y horizontal, z horizontal.
AXIS_HORIZONTAL = (
    (Q, 0.0), (-Q, 0.0), (Q, 4 * Q), (-Q, 4 * Q),
    (0.0, Q), (0.0, 3 * Q), (0.0, -Q), (0.0, -3 * Q),
    (Q, 2 * Q), (-Q, 2 * Q), (Q, -2 * Q), (-Q, -2 * Q),
)  # fmt: skip


@dataclass(frozen=True)
class Dwell:
    """Hold the table at ``angles`` (rad, (outer, middle, inner)) for ``dwell_s`` after ``settle_s``."""

    angles: tuple[float, float, float]
    dwell_s: float
    settle_s: float


@dataclass(frozen=True)
class Plateau:
    """Turn one gimbal (0 outer, 1 middle, 2 inner) at ``rate`` (rad/s) from ``angles`` for ``duration_s``;
    the window starts ``settle_s`` after the rate is reached."""

    angles: tuple[float, float, float]
    axis: int
    rate: float
    duration_s: float
    settle_s: float


@dataclass(frozen=True)
class Schedule:
    dwells: tuple[Dwell, ...]
    plateaus: tuple[Plateau, ...] = ()


def gravity_direction(angles: np.ndarray) -> np.ndarray:
    """u, the up direction in the body frame of a level table with the default mounting, (N, 3)."""
    angles = np.atleast_2d(angles)
    middle, inner = angles[:, 1], angles[:, 2]
    return np.column_stack((-np.sin(inner) * np.cos(middle), np.sin(middle), np.cos(inner) * np.cos(middle)))


def position_angles(count: int = 18, outer: float = 0.0) -> np.ndarray:
    """Gimbal angles (rad) of the 6- or 18-position scheme (axis up/down first), (count, 3)."""
    if count not in (6, 18):
        raise ValueError(f"the position scheme has 6 or 18 positions, not {count}")
    pairs = AXIS_UP_DOWN + (AXIS_HORIZONTAL if count == 18 else ())
    return np.array([(outer, middle, inner) for middle, inner in pairs])


def default_schedule(positions: int = 18, dwell_s: float = 20.0, settle_s: float = 2.0,
                     rate: float = 10.0 * DEG, plateau_s: float = 36.0, axes: tuple[int, ...] = (0, 1, 2)) -> Schedule:
    """The positions (dwell each) and plateaus of both signs about each of ``axes`` (0 outer, 1 middle, 2 inner;
    the outer and inner axes turn from the zero position; the middle axis sweeps across its range);
    ``plateau_s = 0``: no plateaus."""
    dwells = tuple(Dwell(tuple(a), dwell_s, settle_s) for a in position_angles(positions))
    plateaus = []
    for axis in axes if plateau_s > 0 else ():
        for sign in (1.0, -1.0):
            if axis == 1:  # the middle gimbal cannot turn through a full circle: sweep it across its range
                start, duration = -sign * MIDDLE_SWEEP / 2.0, min(plateau_s, MIDDLE_SWEEP / rate)
            else:
                start, duration = 0.0, plateau_s
            angles = (0.0, start, 0.0)
            plateaus.append(Plateau(angles, axis, sign * rate, duration, settle_s))
    return Schedule(dwells, tuple(plateaus))


def schedule_from_config(config: CalibrationConfig) -> Schedule:
    """The schedule a ``calibration:`` block describes (angles converted to rad)."""
    count = config.positions if isinstance(config.positions, int) else 6
    schedule = default_schedule(count, config.dwell_s, config.settle_s, config.plateau_rate_dps * DEG,
                                config.plateau_s, tuple(GIMBAL_AXES.index(a) for a in config.plateau_axes))
    if isinstance(config.positions, int):
        return schedule
    return replace(schedule, dwells=tuple(Dwell(tuple(a * DEG for a in angles), config.dwell_s, config.settle_s)
                                          for angles in config.positions))


def check_limits(schedule: Schedule, limits: LimitsConfig) -> None:
    """Raise ValueError naming the first step outside the table's position or rate limits."""
    low = np.array(limits.position_min_deg) * DEG
    high = np.array(limits.position_max_deg) * DEG
    steps = [(f"position {k + 1}", d.angles, None) for k, d in enumerate(schedule.dwells)]
    steps += [(f"plateau {k + 1}", p.angles, p) for k, p in enumerate(schedule.plateaus)]
    for name, angles, plateau in steps:
        for axis, angle in enumerate(angles):
            if plateau is not None and plateau.axis == axis and axis != 1:
                continue  # a continuously turning outer or inner axis: rate limit only
            if not low[axis] - 1e-12 <= angle <= high[axis] + 1e-12:
                raise ValueError(f"calibration schedule {name}: {GIMBAL_AXES[axis]} angle {angle / DEG:g} deg is "
                                 f"outside the table limits [{low[axis] / DEG:g}, {high[axis] / DEG:g}] deg")
        if plateau is not None:
            limit = limits.rate_dps[plateau.axis] * DEG
            if abs(plateau.rate) > limit:
                raise ValueError(f"calibration schedule {name}: {GIMBAL_AXES[plateau.axis]} rate "
                                 f"{plateau.rate / DEG:g} deg/s exceeds the table limit {limit / DEG:g} deg/s")
            if plateau.axis == 1:
                sweep = plateau.angles[1] + plateau.rate * plateau.duration_s
                if not low[1] - 1e-12 <= sweep <= high[1] + 1e-12:
                    raise ValueError(f"calibration schedule {name}: the middle axis would reach {sweep / DEG:g} deg, "
                                     f"outside the table limits [{low[1] / DEG:g}, {high[1] / DEG:g}] deg")


def schedule_duration(schedule: Schedule, limits: LimitsConfig, margin_s: float = 0.5) -> float:
    """Seconds the table needs for the schedule from the zero position: each step's rest-to-rest move at the
    rate and acceleration limits (the slowest axis), its settle time and window, ``margin_s`` to confirm
    arrival; a plateau adds the ramp to its rate and leaves its axis where the turn ended."""
    rate, accel = np.array(limits.rate_dps) * DEG, np.array(limits.accel_dps2) * DEG
    here, total = np.zeros(3), 0.0
    for step in list(schedule.dwells) + list(schedule.plateaus):
        distance = np.abs(np.array(step.angles) - here)
        move = np.where(distance > rate**2 / accel, distance / rate + rate / accel, 2.0 * np.sqrt(distance / accel))
        total += float(np.max(move)) + margin_s + step.settle_s
        here = np.array(step.angles, dtype=float)
        if isinstance(step, Dwell):
            total += step.dwell_s
            continue
        ramp = abs(step.rate) / accel[step.axis]
        total += ramp + margin_s + step.duration_s
        here[step.axis] += step.rate * (ramp / 2.0 + step.settle_s + step.duration_s)
    return total
