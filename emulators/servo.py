"""The emulated turntable servo: per-axis modes, demands, limits and interlocks, in the controller interface's terms.

The motion the table performs is a :class:`ServoMotion`: per axis, consecutive pieces of the analytic
profiles of :mod:`emulators.motion`, so the truth model integrates it exactly. Until a command
changes an axis, it performs the configured ``turntable.motion`` from t = 0. A command takes effect
at the first sync pulse after everything already emitted (:meth:`Servo.commit`); from there the axis

- Off: brakes to rest at its acceleration limit and stays there;
- Position: brakes, then makes a rest-to-rest trapezoidal move to the demand at its rate and
  acceleration limits, and holds;
- Rate: ramps to the demanded rate at its acceleration limit; an axis with a position range under one
  turn stops at its position limit (status bit "limit reached");
- Synthesis: moves like Position to the oscillation's start point ``demand + amplitude sin(phase)``,
  then oscillates ``demand + amplitude sin(2 pi f (t - t_s) + phase)`` from the pulse t_s on which
  it arrives. The oscillation starts with a rate step of ``amplitude 2 pi f cos(phase)`` (an ideal
  velocity loop), which the demand checks keep within the rate limit.

Demands and the planned motion are true gimbal angles; what the table reports (:meth:`Servo.reading`,
the ``tts1`` frames in :mod:`emulators.sources`) is the encoder reading, the true angle minus
``turntable.zero_offset_arcsec``. The emulated tables (:mod:`emulators.acutrol_table`,
:mod:`emulators.aerosmith_table`) translate their command languages to its methods.

Limits are kept per mode (the Acutrol's are); a demand outside those of the mode it serves is
:class:`Refused`, a mode other than Off with open interlocks too. An interlock trip
(``turntable.interlock_trip_at_s``) opens every axis' interlocks and latches a fault: the axes switch
Off and brake; a reset clears the fault and closing the interlocks servoes the axes again.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from drivers.table_controller import MOTION_MODES
from drivers.tts1 import Mode, Status, status_byte
from emulators.motion import (
    ConstantRate,
    MotionProfile,
    Positions,
    Ramp,
    Swing,
    motion_breaks,
)
from hil.config import LimitsConfig, MotionConfig, TurntableConfig
from hil.samples import GIMBAL_AXES
from hil.units import ARCSEC, DEG
from hil.vocabulary import TableMode

_TTS1_MODE = {TableMode.OFF: Mode.OFF, TableMode.POSITION: Mode.POSITION, TableMode.RATE: Mode.RATE,
              TableMode.SYNTHESIS: Mode.SYNTHESIS}
_RANK = tuple(_TTS1_MODE)  # the table's tts1 mode is the most active of its axes' modes
_DEMAND_MODE = {"rate": TableMode.RATE, "oscillator": TableMode.SYNTHESIS}  # a demand's mode; else position
_STILL = 1e-12  # rad/s; below this an axis counts as not moving


@dataclass(frozen=True)
class Piece:
    """From ``start`` on, one axis follows column ``column`` of ``profile(t - origin)``, in this state."""

    start: float
    origin: float
    profile: MotionProfile
    column: int
    mode: TableMode
    interlocks_closed: bool = True
    fault: bool = False


@dataclass(frozen=True)
class ServoMotion:
    """The performed motion: per axis (outer, middle, inner) the pieces in start order."""

    axes: tuple[tuple[Piece, ...], tuple[Piece, ...], tuple[Piece, ...]]

    @cached_property
    def _starts(self) -> tuple[np.ndarray, ...]:
        return tuple(np.array([p.start for p in pieces]) for pieces in self.axes)

    def _active(self, axis: int, t: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self._starts[axis], t, side="right") - 1, 0, None)

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        angles, rates = np.empty((len(t), 3)), np.empty((len(t), 3))
        for axis, pieces in enumerate(self.axes):
            active = self._active(axis, t)
            for k in np.unique(active):
                p, sel = pieces[k], active == k
                a, r = p.profile(t[sel] - p.origin)
                angles[sel, axis], rates[sel, axis] = a[:, p.column], r[:, p.column]
        return angles, rates

    def breaks(self, t0: float, t1: float) -> np.ndarray:
        """Piece starts and the pieces' own kinks inside (t0, t1)."""
        found = []
        for pieces in self.axes:
            for k, p in enumerate(pieces):
                end = pieces[k + 1].start if k + 1 < len(pieces) else math.inf
                lo, hi = max(t0, p.start), min(t1, end)
                if lo >= hi:
                    continue
                if p.start > t0:
                    found.append(np.array([p.start]))
                found.append(motion_breaks(p.profile, lo - p.origin, hi - p.origin) + p.origin)
        return np.unique(np.concatenate(found)) if found else np.empty(0)

    def piece_at(self, axis: int, t: float) -> Piece:
        return self.axes[axis][int(self._active(axis, np.array([t]))[0])]

    def status(self, t: np.ndarray, limits: LimitsConfig) -> np.ndarray:
        """The ``tts1`` status byte at each instant t."""
        angles, rates = self(t)
        out = np.empty(len(t), dtype=int)
        low, high = np.array(limits.position_min_deg) * DEG, np.array(limits.position_max_deg) * DEG
        limited = high - low < 2.0 * math.pi
        at_limit = (limited & ((angles <= low + 1e-9) | (angles >= high - 1e-9))).any(axis=1)
        moving = (np.abs(rates) > _STILL).any(axis=1)
        active = [self._active(axis, t) for axis in range(3)]
        for i in range(len(t)):
            pieces = [self.axes[axis][active[axis][i]] for axis in range(3)]
            flags = Status(0)
            if all(p.interlocks_closed for p in pieces):
                flags |= Status.INTERLOCKS_CLOSED
            if moving[i]:
                flags |= Status.MOVING
            if at_limit[i]:
                flags |= Status.LIMIT_REACHED
            if any(p.fault for p in pieces):
                flags |= Status.FAULT
            out[i] = status_byte(flags, _TTS1_MODE[max((p.mode for p in pieces), key=_RANK.index)])
        return out


class Refused(ValueError):
    """A command the table does not carry out; ``reason`` is ``limit``, ``interlock`` or ``argument``."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


def _names(axes: list[int]) -> str:
    return ", ".join(GIMBAL_AXES[k] for k in axes)


def _full(value: float) -> np.ndarray:
    return np.full(3, float(value))


@dataclass
class _Demand:
    """What one axis is told to do (deg, deg/s, Hz)."""

    mode: TableMode
    position: float = 0.0
    rate: float = 0.0
    oscillator: tuple[float, float, float] = (0.0, 0.0, 0.0)  # amplitude deg, frequency Hz, phase deg


class Servo:
    """The table's controller: holds the demands and limits, plans the motion.

    Thread-safe through :attr:`lock`: the command server calls the commands, the emulator's pulse loop
    :meth:`commit` and reads :attr:`motion` and :attr:`revision` (bumped by every change of the plan).
    """

    def __init__(self, table: TurntableConfig, rate_hz: float, initial: MotionProfile) -> None:
        self.rate_hz = rate_hz
        self.limits = table.limits  # the configured ones: where the tts1 status reports "limit reached"
        self.mode_limits = {mode: table.limits for mode in TableMode}  # what the table was told, per mode
        self.lock = threading.RLock()
        self.revision = 0
        self.sync_output = True
        self.horizon = -1.0 / rate_hz  # latest trial time already emitted
        self.trip_at = table.interlock_trip_at_s
        self.zero_offset_deg = np.array(table.zero_offset_arcsec) * ARCSEC / DEG
        mode = MOTION_MODES[table.motion.kind]
        self.demands = [_configured_demand(table.motion, axis) for axis in GIMBAL_AXES]
        self.motion = ServoMotion(tuple((Piece(0.0, 0.0, initial, k, mode),) for k in range(3)))

    # Time

    def next_pulse_time(self) -> float:
        """The first pulse after everything emitted: where a change takes effect."""
        return (math.floor(self.horizon * self.rate_hz + 1e-9) + 1) / self.rate_hz

    def commit(self, latest: float) -> None:
        """Record that frames depending on the motion up to ``latest`` have been emitted."""
        self.horizon = max(self.horizon, latest)

    def advance(self, t: float) -> None:
        """Apply a scheduled interlock trip due by trial time ``t`` (before a frame latched at t is made)."""
        if self.trip_at is not None and t >= self.trip_at:
            trip = max(math.ceil(self.trip_at * self.rate_hz - 1e-9) / self.rate_hz, self.next_pulse_time())
            self.trip_at = None
            self._change(range(3), trip, interlocks_closed=False, fault=True, mode=TableMode.OFF)

    # Commands (the controller interface's vocabulary; the emulated tables translate their dialects to it)

    def set_mode(self, axes: list[int], mode: TableMode | str) -> None:
        """A :class:`TableMode` on columns ``axes`` (ValueError for another word); any but off needs closed
        interlocks."""
        mode = TableMode(mode)
        with self.lock:
            t = self.next_pulse_time()
            if mode != TableMode.OFF and not all(self._state(k, t).interlocks_closed for k in axes):
                raise Refused(f"interlock open on the {_names(axes)} axis: close it before mode {mode}", "interlock")
            self._change(axes, t, mode=mode)

    def demand(self, axes: list[int], kind: str, values: tuple[float, ...]) -> None:
        """A demand (``position`` deg, ``delta`` deg, ``rate`` deg/s, ``oscillator`` amplitude deg, Hz,
        phase deg), checked against the limits of the mode it serves, then applied."""
        with self.lock:
            if kind == "delta":
                kind, values = "position", (self.demands[axes[0]].position + values[0],)
            for k in axes:
                self._check_demand(k, kind, values)
            for k in axes:
                d = self.demands[k]
                if kind == "position":
                    d.position = values[0]
                elif kind == "rate":
                    d.rate = values[0]
                else:
                    d.oscillator = tuple(values)
            self._change(axes, self.next_pulse_time())

    def interlock(self, axes: list[int], action: str) -> None:
        """``close``, ``open`` or ``reset`` (the latched fault, every axis) the interlocks."""
        with self.lock:
            t = self.next_pulse_time()
            if action == "reset":
                self._change([k for k in range(3) if self._state(k, t).fault], t, fault=False)
            elif action == "close":
                if any(self._state(k, t).fault for k in axes):
                    raise Refused("interlock fault latched: reset it first", "interlock")
                self._change(axes, t, interlocks_closed=True)
            else:
                self._change(axes, t, interlocks_closed=False, mode=TableMode.OFF)

    def set_limit(self, mode: TableMode, axes: list[int], kind: str, value: float) -> None:
        """The ``rate`` (deg/s), ``accel`` (deg/s^2), ``low`` or ``high`` (deg) limit of one mode."""
        with self.lock:
            lim = self.mode_limits[mode]
            if kind in ("low", "high"):
                low = _put(lim.position_min_deg, axes, value) if kind == "low" else lim.position_min_deg
                high = _put(lim.position_max_deg, axes, value) if kind == "high" else lim.position_max_deg
                if not all(lo < hi for lo, hi in zip(low, high)):
                    raise Refused(f"position limits need low < high, got {value:g}", "argument")
                update = {"position_min_deg": low, "position_max_deg": high}
            else:
                if not value > 0:
                    raise Refused(f"the {kind} limit must be positive, got {value:g}", "argument")
                key = "rate_dps" if kind == "rate" else "accel_dps2"
                update = {key: _put(getattr(lim, key), axes, value)}
            self.mode_limits[mode] = lim.model_copy(update=update)

    # Queries

    def mode(self, k: int) -> TableMode:
        return self.demands[k].mode

    def interlock_state(self, k: int) -> str:
        """``closed``, ``open`` or ``fault`` (latched) for column k."""
        piece = self._state(k, self.next_pulse_time())
        return "fault" if piece.fault else "closed" if piece.interlocks_closed else "open"

    def reading(self, k: int) -> tuple[float, float, float]:
        """Encoder position (deg), rate (deg/s) and acceleration (deg/s^2, the rate's change over the last
        pulse period) of column k at the latest instant emitted."""
        with self.lock:
            t = max(self.horizon, 0.0)
            angles, rates = self.motion(np.array([t - 1.0 / self.rate_hz, t]))
        rate = math.degrees(float(rates[1, k]))
        return (math.degrees(float(angles[1, k])) - self.zero_offset_deg[k], rate,
                (rate - math.degrees(float(rates[0, k]))) * self.rate_hz)

    def limit(self, mode: TableMode, k: int, kind: str) -> float:
        lim = self.mode_limits[mode]
        return {"rate": lim.rate_dps, "accel": lim.accel_dps2, "low": lim.position_min_deg,
                "high": lim.position_max_deg}[kind][k]

    def _check_demand(self, k: int, kind: str, values: tuple) -> None:
        name = GIMBAL_AXES[k]
        lim = self.mode_limits[_DEMAND_MODE.get(kind, TableMode.POSITION)]
        low, high = lim.position_min_deg[k], lim.position_max_deg[k]
        if kind == "position":
            spans = (values[0], values[0])
        elif kind == "rate":
            if abs(values[0]) > lim.rate_dps[k]:
                raise Refused(f"rate {values[0]:g} deg/s exceeds the {name} limit {lim.rate_dps[k]:g}", "limit")
            return
        else:
            amplitude, frequency, _ = values
            if amplitude < 0 or frequency < 0:
                raise Refused("oscillator amplitude and frequency must be >= 0", "argument")
            omega = 2.0 * math.pi * frequency
            if amplitude * omega > lim.rate_dps[k] or amplitude * omega**2 > lim.accel_dps2[k]:
                raise Refused(f"oscillation {amplitude:g} deg at {frequency:g} Hz exceeds the {name} rate or "
                              "acceleration limit", "limit")
            center = self.demands[k].position
            spans = (center - amplitude, center + amplitude)
        if high - low < 360.0 and not (low <= spans[0] and spans[1] <= high):
            raise Refused(f"position {spans[0]:g}..{spans[1]:g} deg is outside the {name} limits "
                          f"[{low:g}, {high:g}]", "limit")

    # Planning

    def _state(self, k: int, t: float) -> Piece:
        return self.motion.piece_at(k, t)

    def _change(self, axes, t: float, **state) -> None:
        """Re-plan ``axes`` from pulse time t with their demands and ``state`` changes."""
        planned = list(self.motion.axes)
        for k in axes:
            flags = replace(self._state(k, t), **state)
            self.demands[k].mode = flags.mode
            kept = tuple(p for p in planned[k] if p.start < t)
            planned[k] = kept + self._plan(k, t, flags)
        self.motion = ServoMotion(tuple(planned))
        self.revision += 1

    def _plan(self, k: int, t: float, flags: Piece) -> tuple[Piece, ...]:
        """The pieces of axis k from t: brake or ramp, move, then hold, rotate or oscillate."""
        angles, rates = self.motion(np.array([t]))
        p0, v0 = float(angles[0, k]), float(rates[0, k])
        d, lim = self.demands[k], self.mode_limits[flags.mode]
        accel = lim.accel_dps2[k] * DEG
        pieces: list[Piece] = []

        def add(start: float, profile: MotionProfile, origin: float | None = None) -> None:
            pieces.append(replace(flags, start=start, origin=start if origin is None else origin,
                                  profile=profile, column=k))

        if flags.mode == TableMode.RATE:
            v1 = d.rate * DEG
            t1 = t + abs(v1 - v0) / accel
            add(t, Ramp(_full(p0), _full(v0), _full(math.copysign(accel, v1 - v0))))
            p1 = p0 + (v0 + v1) / 2.0 * (t1 - t)
            add(t1, ConstantRate(_full(p1), _full(v1)))
            self._stop_at_limit(k, t1, p1, v1, accel, add)
            return tuple(pieces)
        t1, p1 = t, p0
        if abs(v0) > _STILL:  # brake to rest
            t1 = t + abs(v0) / accel
            p1 = p0 + v0 * (t1 - t) / 2.0
            add(t, Ramp(_full(p0), _full(v0), _full(-math.copysign(accel, v0))))
        if flags.mode == TableMode.OFF:
            add(t1, ConstantRate(_full(p1), np.zeros(3)))
            return tuple(pieces)
        amplitude, frequency, phase = d.oscillator[0] * DEG, d.oscillator[1], d.oscillator[2] * DEG
        target = d.position * DEG + (amplitude * math.sin(phase) if flags.mode == TableMode.SYNTHESIS else 0.0)
        move = Positions(np.array([_full(p1), _full(target)]), np.array([0.0, 1.0]), lim.rate_dps[k] * DEG, accel)
        add(t1, move)
        if flags.mode == TableMode.SYNTHESIS:
            arrive = t1 + move.segments()[0][2]
            t_s = math.ceil(arrive * self.rate_hz - 1e-9) / self.rate_hz
            add(t_s, Swing(_full(amplitude), _full(2.0 * math.pi * frequency), _full(phase), _full(d.position * DEG)))
        return tuple(pieces)

    def _stop_at_limit(self, k: int, t1: float, p1: float, v1: float, accel: float, add) -> None:
        """Rate mode on an axis with limited travel: decelerate so that it halts exactly at the limit."""
        lim = self.mode_limits[TableMode.RATE]
        low, high = lim.position_min_deg[k] * DEG, lim.position_max_deg[k] * DEG
        if high - low >= 2.0 * math.pi or abs(v1) <= _STILL:
            return
        end = high if v1 > 0 else low
        brake = v1 * v1 / (2.0 * accel)
        t2 = t1 + max(abs(end - p1) - brake, 0.0) / abs(v1)
        p2 = p1 + v1 * (t2 - t1)
        add(t2, Ramp(_full(p2), _full(v1), _full(-math.copysign(accel, v1))))
        t3 = t2 + abs(v1) / accel
        add(t3, ConstantRate(_full(p2 + v1 * (t3 - t2) / 2.0), np.zeros(3)))

    def status_now(self) -> int:
        return int(self.motion.status(np.array([max(self.horizon, 0.0)]), self.limits)[0])


def _configured_demand(motion: MotionConfig, axis: str) -> _Demand:
    """The demand that the configured motion of one axis stands for (its first position for ``positions``)."""
    a = getattr(motion.axes, axis)
    if motion.kind == "positions":
        return _Demand(TableMode.POSITION, getattr(motion.positions[0], f"{axis}_deg"))
    frequency = 0.0 if a.period_s is None else 1.0 / a.period_s
    return _Demand(MOTION_MODES[motion.kind], a.center_deg, a.rate_dps,
                   (a.amplitude_deg, frequency, a.phase_deg))


def _put(values: tuple, axes: list[int], value: float) -> tuple:
    out = list(values)
    for k in axes:
        out[k] = value
    return tuple(out)
