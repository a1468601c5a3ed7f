"""Sensor-triad error model of the multi-position calibration (its weighted least squares:
:mod:`hil.estimation.calibration_fit`).

Forward model (three-stage self-calibration 2018, Eq. (6), written as the emulator applies it, term by
term; r is the reference, specific force or angular rate in the body frame, SI):

    v = (I + S) C r,    y = v + K_nl v^2 + b        (squares element-wise)

S = diag(scale errors), C = I + M with the misalignment angles (xy, xz, yx, yz, zx, zy) placed as in
Eq. (5): M = [[0, xz, -xy], [-yz, 0, yx], [zy, -zx, 0]]. The reference is computed at the true gimbal
angles, encoder reading plus zero offset (outer, middle, inner).

The parameter vector theta holds, in this order, the terms of :data:`TERMS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

AXES = "xyz"
MISALIGNMENT = ("xy", "xz", "yx", "yz", "zx", "zy")
# (row, column, sign) of each misalignment angle in M, Eq. (5).
MISALIGNMENT_ENTRIES = ((0, 2, -1.0), (0, 1, 1.0), (1, 2, 1.0), (1, 0, -1.0), (2, 1, -1.0), (2, 0, 1.0))
ZERO_OFFSETS = ("outer", "middle", "inner")
TERMS = (
    tuple(f"bias_{a}" for a in AXES)
    + tuple(f"scale_{a}" for a in AXES)
    + tuple(f"misalignment_{p}" for p in MISALIGNMENT)
    + tuple(f"nonlinearity_{a}" for a in AXES)
    + tuple(f"zero_offset_{g}" for g in ZERO_OFFSETS)
)
INDEX = {name: k for k, name in enumerate(TERMS)}
BIAS, SCALE, MIS, NONLIN, ZERO = (slice(0, 3), slice(3, 6), slice(6, 12), slice(12, 15), slice(15, 18))
ZERO_STEP = 1e-6  # rad, central-difference step of the reference in the zero offsets
NOISE_FLOOR = 1e-9  # a sample's noise below this fraction of its window's mean is rounding, not noise


@dataclass(frozen=True)
class Window:
    """One dwell or rate-plateau window: the IMU's mean outputs and the table's encoder readings.

    ``angles`` (M, 3) rad: encoder angles (outer, middle, inner) at the midpoints of the IMU intervals of
    the window (plain mean = the window mean; a dwell may give one row, its mean); ``rates`` (3,) rad/s: the gimbal rates of a plateau (zero for a dwell);
    ``specific_force`` (3,) m/s^2 = sum(dv) / window length; ``angular_rate`` (3,) rad/s = sum(dtheta) /
    window length; ``samples``: IMU samples averaged (the weight of the window); ``duration_s``: its length.
    ``force_noise`` and ``rate_noise`` (3,): the variance of one sample's specific force (m^2/s^4) and angular
    rate (rad^2/s^2) measured in the window (:func:`sample_noise`), None where unknown.
    """

    angles: np.ndarray
    rates: np.ndarray
    specific_force: np.ndarray
    angular_rate: np.ndarray
    samples: int
    duration_s: float
    force_noise: np.ndarray | None = None
    rate_noise: np.ndarray | None = None

    @property
    def static(self) -> bool:
        return not np.any(self.rates)


def window_from_samples(dtheta: np.ndarray, dv: np.ndarray, dt: np.ndarray, angles: np.ndarray,
                        rates: Sequence[float] = (0.0, 0.0, 0.0)) -> Window:
    """A :class:`Window` from the aligned samples inside it: increments (N, 3), their intervals dt (N,) s,
    and the encoder angles (M, 3) rad latched through the window."""
    span = float(np.sum(dt))
    dt = np.asarray(dt, float)[:, None]
    return Window(np.atleast_2d(np.asarray(angles, float)), np.asarray(rates, float),
                  np.sum(dv, axis=0) / span, np.sum(dtheta, axis=0) / span, len(dt), span,
                  sample_noise(np.asarray(dv) / dt), sample_noise(np.asarray(dtheta) / dt))


def sample_noise(values: np.ndarray) -> np.ndarray | None:
    """The variance of one sample's white noise (3,) from the successive differences of the window's samples
    (N, 3), ``mean((x_k - x_k-1)^2) / 2``: blind to a slow change of the signal (the earth's rate turning in a
    plateau), which a plain variance would count as noise. None for fewer than two samples."""
    if len(values) < 2:
        return None
    return np.mean(np.diff(values, axis=0) ** 2, axis=0) / 2.0


def measured_noise(noise: Sequence[np.ndarray | None], means: np.ndarray) -> np.ndarray | None:
    """The windows' measured sample variances (their ``force_noise`` or ``rate_noise``) as (N, 3), when every
    window has them above :data:`NOISE_FLOOR` of its mean's size (``means`` (N, 3), the windows' specific force
    or angular rate); else None: noise-free data (a float64 simulation's rounding) have no scale to weigh by."""
    if any(n is None for n in noise):
        return None
    noise = np.array(noise)
    floor = (NOISE_FLOOR * np.linalg.norm(means, axis=1))[:, None] ** 2
    return noise if np.all(noise > floor) else None


def window_means(windows: Sequence[Window], zero_offsets: np.ndarray,
                 per_sample: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """Mean over each window's encoder angles (plus the zero offsets) of ``per_sample(angles, rates)``,
    (N, 3): one batched call over all windows' rows."""
    counts = [len(w.angles) for w in windows]
    angles = np.vstack([w.angles for w in windows]) + zero_offsets
    rates = np.repeat(np.array([w.rates for w in windows]), counts, axis=0)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    return np.add.reduceat(per_sample(angles, rates), starts, axis=0) / np.array(counts)[:, None]


def misalignment_matrix(angles: np.ndarray) -> np.ndarray:
    """C = I + M of Eq. (5) from the angles (xy, xz, yx, yz, zx, zy), rad."""
    c = np.eye(3)
    for (row, col, sign), angle in zip(MISALIGNMENT_ENTRIES, angles, strict=True):
        c[row, col] = sign * angle
    return c


def triad_matrix(theta: np.ndarray) -> np.ndarray:
    """K = (I + S) C, the linear part of the forward model."""
    return (1.0 + theta[SCALE])[:, None] * misalignment_matrix(theta[MIS])


def forward(theta: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Sensor outputs y (N, 3) from references r (N, 3): Eq. (6) as in the module docstring."""
    v = reference @ triad_matrix(theta).T
    return v + theta[NONLIN] * v * v + theta[BIAS]


def inverse(theta: np.ndarray, output: np.ndarray) -> np.ndarray:
    """References r (N, 3) from outputs y (N, 3): the exact inverse of :func:`forward`."""
    a = np.atleast_2d(output) - theta[BIAS]
    k = theta[NONLIN]
    # v + k v^2 = a, the root near a, written to stay exact as k -> 0
    v = 2.0 * a / (1.0 + np.sqrt(1.0 + 4.0 * k * a))
    return np.linalg.solve(triad_matrix(theta), v.T).T


def compensate(accel: np.ndarray, gyro: np.ndarray, dtheta: np.ndarray, dv: np.ndarray,
               dt: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Raw increments (N, 3) over intervals dt (s) -> compensated ones: :func:`inverse` of each triad's theta
    (18,) applied to the interval-mean rate and specific force."""
    dt = np.reshape(np.asarray(dt, dtype=float), (-1, 1))
    return inverse(gyro, np.asarray(dtheta) / dt) * dt, inverse(accel, np.asarray(dv) / dt) * dt


def fold_inner_rotation(theta: np.ndarray, inner_zero: float, body_to_mount: np.ndarray | None = None) -> np.ndarray:
    """theta with the inner gimbal's zero offset (rad) folded into the scale and misalignment terms: a turn
    of the whole triad about the inner axis (the mount's y) that no table measurement tells from the misalignment,
    ``K' = K M^T Ry(-inner_zero) M`` with M the triad's mounting (``body_to_mount``, identity by default); the
    terms a calibration finds with the inner zero offset taken as zero."""
    c, s = math.cos(inner_zero), math.sin(inner_zero)
    m = np.eye(3) if body_to_mount is None else np.asarray(body_to_mount, dtype=float)
    k = triad_matrix(theta) @ m.T @ np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]) @ m
    out = np.array(theta, dtype=float)
    out[SCALE] = np.diag(k) - 1.0
    normalised = k / np.diag(k)[:, None]
    out[MIS] = [sign * normalised[row, col] for row, col, sign in MISALIGNMENT_ENTRIES]
    out[ZERO.start + 2] = 0.0
    return out


def forward_jacobian(theta: np.ndarray, reference: np.ndarray,
                     reference_at: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """d y / d theta, (N, 3, 18): analytic in the sensor terms, central differences in the zero offsets.

    ``reference_at(zero_offsets)`` gives the references with the gimbal zero offsets (3,) rad.
    """
    n = len(reference)
    s, c = 1.0 + theta[SCALE], misalignment_matrix(theta[MIS])
    v = reference @ (s[:, None] * c).T
    chain = 1.0 + 2.0 * theta[NONLIN] * v  # d y_i / d v_i
    jac = np.zeros((n, 3, len(TERMS)))
    for i in range(3):
        jac[:, i, BIAS.start + i] = 1.0
        jac[:, i, SCALE.start + i] = chain[:, i] * (reference @ c[i])
        jac[:, i, NONLIN.start + i] = v[:, i] ** 2
    for k, (row, col, sign) in enumerate(MISALIGNMENT_ENTRIES):
        jac[:, row, MIS.start + k] = chain[:, row] * sign * s[row] * reference[:, col]
    zero = theta[ZERO]
    for k in range(3):
        step = np.zeros(3)
        step[k] = ZERO_STEP
        dr = (reference_at(zero + step) - reference_at(zero - step)) / (2.0 * ZERO_STEP)
        jac[:, :, ZERO.start + k] = chain * (dr @ (s[:, None] * c).T)
    return jac
