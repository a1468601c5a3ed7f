"""Which pulse offset between the IMU's counter and the table's makes the gyros agree with the table angles.

With the IMU sample of unwrapped counter ``u`` placed at pulse ``u + d`` (its increments cover the pulses
``(u + d - 1, u + d]``) and the table sample of count ``c`` at pulse ``c``, the gyro increments of the
samples inside a table interval ``(c_j, c_j+1]`` sum to the body's rotation over it, which the angles at
both ends give (``C_n^b(c_j) C_n(c_j+1)^n(c_j) C_b^n(c_j+1)``, the earth's turn included). The mean
square of the difference over the intervals, a constant rate per axis (the gyro biases) removed, is
smallest at the true offset ``d``; a shift by one pulse adds the change of the rotation over one pulse at
both ends of every interval, which a moving table makes large against the gyro noise. A table at rest,
or turning at a constant rate, shows no such change: its time cannot be read from the motion.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from hil.frames import Earth, TableGeometry, table_body_rotation
from hil.pipeline.plausibility import small_rotation_vectors
from hil.samples import ImuSamples, TableSamples

DECISIVE = 25.0  # chi-square gain of the best offset over every other one (5 sigma)
MIN_INTERVALS = 50  # table intervals the best offset must cover
STILL_RAD = 1e-6  # rms change of the table's rotation per interval below which the table shows no motion
NOISE_FLOOR_RAD = 1e-9  # per interval: the float32 resolution of a gyro increment, a floor under the residual
CANDIDATES_AT_ONCE = 256  # candidates whose residuals are formed in one array (bounds the memory)


@dataclass(frozen=True)
class Match:
    """The outcome of a search: the decisive offset (None when there is none), and whether the table moved."""

    offset: int | None
    moving: bool
    intervals: int = 0


class TableRotations:
    """The body rotation vectors (rad) over the table's complete intervals: the intervals start at ``start`` (M,)
    counts and last ``step`` counts."""

    def __init__(self, geometry: TableGeometry, earth: Earth, rate_hz: float, step: int, counts: np.ndarray,
                 angles: np.ndarray) -> None:
        whole = np.flatnonzero(np.diff(counts) == step)
        self.step = step
        self.start = counts[whole]
        relative = table_body_rotation(geometry, earth, np.full(len(whole), step / rate_hz), angles[whole],
                                       angles[whole + 1])
        self.rotation = small_rotation_vectors(relative) if len(whole) else np.zeros((0, 3))

    @property
    def moving(self) -> bool:
        """The rotation per interval changes (more than encoder noise): the motion can tell time."""
        if len(self.rotation) < 2:
            return False
        change = self.rotation - self.rotation.mean(axis=0)
        return bool(np.sqrt(np.mean(np.sum(change ** 2, axis=1))) > STILL_RAD)


def residuals(u: np.ndarray, dtheta: np.ndarray, table: TableRotations, candidates: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate offset d (K,): the mean square gyro-minus-table rotation per interval (rad^2, biases
    removed) and the number of intervals the IMU samples cover completely (an interval with a missing sample
    is left out). ``u`` (N,) unwrapped IMU counters, unique; ``dtheta`` (N, 3)."""
    k = len(candidates)
    out, used = np.full(k, np.inf), np.zeros(k, dtype=np.int64)
    if not len(u) or not len(table.start):
        return out, used
    u0 = int(u.min())
    span = int(u.max()) - u0 + 1
    total = np.zeros((span + 1, 3))
    present = np.zeros(span + 1, dtype=np.int64)
    total[u - u0 + 1] = dtheta
    present[u - u0 + 1] = 1
    total, present = np.cumsum(total, axis=0), np.cumsum(present)
    for first in range(0, k, CANDIDATES_AT_ONCE):
        d = candidates[first:first + CANDIDATES_AT_ONCE, None]
        lo = table.start[None, :] - d - u0 + 1  # cumulative index just before the interval's first sample
        hi = lo + table.step
        inside = (lo >= 0) & (hi <= span)
        lo_c, hi_c = np.clip(lo, 0, span), np.clip(hi, 0, span)
        whole = (inside & (present[hi_c] - present[lo_c] == table.step)).astype(float)
        diff = total[hi_c] - total[lo_c] - table.rotation[None]
        n = whole.sum(axis=1).astype(np.int64)
        mean = np.where(n[:, None] > 0, np.einsum("km,kmi->ki", whole, diff) / np.maximum(n, 1)[:, None], 0.0)
        square = np.einsum("km,kmi->k", whole, (diff - mean[:, None]) ** 2)
        out[first:first + len(d)] = np.where(n > 0, square / np.maximum(n, 1), np.inf)
        used[first:first + len(d)] = n
    return out, used


def best_offset(u: np.ndarray, dtheta: np.ndarray, table: TableRotations, candidates: np.ndarray) -> Match:
    """The candidate whose residual beats every other one's by :data:`DECISIVE` in chi-square (the best
    one's residual taken as the noise) over at least :data:`MIN_INTERVALS` intervals, and not at the edge of
    the candidates (the true one may lie beyond); None where the data do not decide."""
    moving = table.moving
    if not moving or len(candidates) < 3:
        return Match(None, moving)
    score, used = residuals(u, dtheta, table, candidates)
    score[used < MIN_INTERVALS // 2] = np.inf  # too little overlap to compare at all (the best needs them all)
    best = int(np.argmin(score))
    n = int(used[best])
    if n < MIN_INTERVALS or best in (0, len(candidates) - 1):
        return Match(None, moving, n)
    noise = max(float(score[best]), NOISE_FLOOR_RAD ** 2)
    others = np.delete(score, best)
    if (float(others.min()) - float(score[best])) * n / noise < DECISIVE:
        return Match(None, moving, n)
    return Match(int(candidates[best]), moving, n)


class PairedMotion:
    """The last ``span_s`` of paired IMU increments and table angles on the pulse line (pulses (N,), values
    (N, 3)), which the motion searches and checks match; ``rotations`` builds the table's interval rotations
    from (pulses, angles) and ``table_first`` is the table's first pulse."""

    def __init__(self, rate_hz: float, span_s: float,
                 rotations: Callable[[np.ndarray, np.ndarray], TableRotations]) -> None:
        self.span = span_s * rate_hz
        self.rotations = rotations
        self.imu = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))  # (pulse, dtheta)
        self.table = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))  # (pulse, angles)
        self.table_first: int | None = None

    def add_imu(self, pulses: np.ndarray, dtheta: np.ndarray) -> None:
        self.imu = kept(self.imu, pulses, dtheta, self.span)

    def add_table(self, pulses: np.ndarray, angles: np.ndarray) -> None:
        if self.table_first is None:
            self.table_first = int(pulses[0])
        self.table = kept(self.table, pulses, angles, self.span)

    def forget_imu(self, shift: int | None = None) -> None:
        """The IMU's history dropped (its pairing broke), or moved ``shift`` pulses (re-paired nearby)."""
        pulses, dtheta = self.imu
        self.imu = (pulses[:0], dtheta[:0]) if shift is None else (pulses + shift, dtheta)

    def forget_table(self) -> None:
        self.table = (self.table[0][:0], self.table[1][:0])

    def match(self, pulses: np.ndarray, dtheta: np.ndarray, candidates: np.ndarray) -> Match:
        """The offset among ``candidates`` that makes the IMU's increments at ``pulses`` agree with the table."""
        return best_offset(pulses, dtheta, self.rotations(*self.table), candidates)

    def match_held(self, held: ImuSamples | TableSamples, candidates: np.ndarray) -> Match:
        """The offset among ``candidates`` that puts a waiting stream's samples where they agree with the other
        stream's history: the IMU's against the table's, the table's against the IMU's (the IMU shifted by minus
        the offset against the table at its counts)."""
        if isinstance(held, ImuSamples):
            return self.match(held.sync_index, held.dtheta, candidates)
        match = best_offset(*self.imu, self.rotations(held.sync_index, held.angles), -candidates)
        return match if match.offset is None else replace(match, offset=-match.offset)


def kept(history: tuple[np.ndarray, np.ndarray], pulses: np.ndarray, values: np.ndarray, span: float
         ) -> tuple[np.ndarray, np.ndarray]:
    """History plus new samples, the last ``span`` pulses of it (trimmed when twice that is held)."""
    p, v = np.concatenate((history[0], pulses)), np.concatenate((history[1], values))
    if len(p) and p[-1] - p[0] > 2 * span:
        first = int(np.searchsorted(p, p[-1] - span))
        p, v = p[first:], v[first:]
    return p, v
