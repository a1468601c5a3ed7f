"""Accelerometer calibration over dwell positions: the device-level stages of the three-stage paper (2018).

1. Coarse (Eq. (7)): the vector model of :mod:`hil.estimation.calibration_model` without the nonlinearity,
   least squares over the positions for bias, scale, the six misalignment angles and the gimbal zero
   offsets. Leaving K_nl out biases the terms whose regressors are even in the gravity direction (bias,
   middle zero offset): the 18 positions come in pairs u, -u.
2. Fine (Eqs. (8)-(17)): half the difference of squared magnitudes, ``(g^2 - |f_hat|^2) / 2`` with
   ``f_hat`` the specific force the current estimate gives, against the exact derivatives of
   ``|f_hat|^2 / 2`` in bias, scale, K_nl and the three symmetric misalignment pairs (Eq. (16)'s columns
   f, f^2, f^3 and the cross products to first order), iterated to convergence. Magnitudes do not see a
   rotation, so the pairs (xz, yz), (xy, zy), (yx, zx) enter only as sums (the paper's remark after
   Eq. (17)) and the zero offsets not at all.
3. Refined: the vector model again with every term, started from the fine solution, which gives the
   rotation part of the misalignment and the middle zero offset free of the nonlinearity, and one
   covariance for all terms.

Zero offsets are the true gimbal angle minus the encoder reading. The outer one does not change the
specific force (the outer axis is vertical) and is never fitted here; the inner one is a rotation of the
whole triad about the inner axis, which the misalignment angles already contain, and the rank test
reports it so.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from hil.estimation.calibration_fit import Fit, Observations, full_scale_effects, least_squares
from hil.estimation.calibration_model import (
    INDEX,
    MISALIGNMENT_ENTRIES,
    NONLIN,
    TERMS,
    Window,
    forward,
    forward_jacobian,
    inverse,
    measured_noise,
    misalignment_matrix,
    triad_matrix,
    window_means,
)
from hil.frames import Earth, TableGeometry

ACCEL_GROUPS = ("bias", "scale", "misalignment", "nonlinearity", "zero_offset")
OUTER_ZERO_REASON = ("the outer axis is vertical: turning about it leaves gravity in the body frame unchanged, "
                     "so no accelerometer measurement depends on its zero offset")
# Symmetric misalignment pairs seen by magnitudes: (first, second, sign of second) with M_rc + M_cr = sum.
PAIRS = (("misalignment_xz", "misalignment_yz", -1.0), ("misalignment_xy", "misalignment_zy", -1.0),
         ("misalignment_yx", "misalignment_zx", -1.0))
PAIR_NAMES = ("misalignment_xz-yz", "misalignment_zy-xy", "misalignment_yx-zx")
DEFAULT_TOLERANCE = 1e-6


@dataclass(frozen=True)
class AccelCalibration:
    """The three stages' fits (theta and sigma over :data:`TERMS`, SI) and the gravity used (m/s^2).

    ``refined`` is the result; ``raw_residuals`` (N, 3) m/s^2 are outputs minus the error-free model.
    """

    coarse: Fit
    fine: Fit
    refined: Fit
    gravity: float
    raw_residuals: np.ndarray


def specific_force_reference(windows: Sequence[Window], earth: Earth, geometry: TableGeometry,
                             zero_offsets: np.ndarray) -> np.ndarray:
    """f^b = C_n^b [0, 0, g] averaged over each window's encoder angles plus the zero offsets, (N, 3)."""
    return window_means(windows, zero_offsets, lambda angles, _: earth.f_n @ geometry.attitude_matrix(angles)[0])


def raw_force_residuals(windows: Sequence[Window], earth: Earth, geometry: TableGeometry) -> np.ndarray:
    """(N, 3) m/s^2: each window's specific force minus gravity at its encoder angles, the error-free model
    with zero offsets zero (the residual before calibration)."""
    y = np.array([w.specific_force for w in windows])
    return y - specific_force_reference(windows, earth, geometry, np.zeros(3))


def calibrate_accelerometers(windows: Sequence[Window], earth: Earth, geometry: TableGeometry,
                             fit: Sequence[str] = ACCEL_GROUPS,
                             tolerance: float = DEFAULT_TOLERANCE) -> AccelCalibration:
    """Coarse, fine and refined stages over the static windows (module docstring); ``fit`` names the term
    groups to estimate (the others stay zero)."""
    static = [w for w in windows if w.static]
    if not static:
        raise ValueError("accelerometer calibration needs dwell windows (zero gimbal rates)")
    y = np.array([w.specific_force for w in static])
    samples = np.array([w.samples for w in static], dtype=float)
    # each sample's variance, measured in its window
    noise = measured_noise([w.force_noise for w in static], y)
    prior = noise if noise is not None else np.ones_like(y)

    def reference_at(zero: np.ndarray) -> np.ndarray:
        return specific_force_reference(static, earth, geometry, zero)

    def vector_model(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        reference = reference_at(theta[15:18])
        return y - forward(theta, reference), forward_jacobian(theta, reference, reference_at)

    effects = full_scale_effects(reference_at(np.zeros(3)))

    def names(groups: Sequence[str]) -> list[str]:
        return [t for t in TERMS if t.rsplit("_", 1)[0] in groups and t != "zero_offset_outer"]

    def vector_fit(theta0: np.ndarray, groups: Sequence[str]) -> Fit:
        chosen = names(groups)
        result = least_squares(theta0, _unit_basis(chosen), chosen,
                               Observations(vector_model, samples, prior, measured=noise is not None), tolerance,
                               effects=effects)
        return _with_outer_reason(result)

    coarse = vector_fit(np.zeros(len(TERMS)), [g for g in fit if g != "nonlinearity"])
    fine = _fine_stage(coarse, y, samples, earth.g, fit, tolerance, noise)
    refined = vector_fit(fine.theta, fit)
    return AccelCalibration(coarse, fine, refined, earth.g, raw_force_residuals(static, earth, geometry))


def _fine_stage(coarse: Fit, y: np.ndarray, samples: np.ndarray, gravity: float, fit: Sequence[str],
                tolerance: float, noise: np.ndarray | None) -> Fit:
    """Eq. (16) iterated: magnitudes against gravity, from the coarse solution; ``noise`` (N, 3) each sample's
    variance per axis as measured in its window (None: the coarse fit's per-axis noise)."""
    columns, chosen = [], []
    for name in TERMS:
        group = name.rsplit("_", 1)[0]
        if group in ("bias", "scale", "nonlinearity") and group in fit:
            columns.append(np.eye(len(TERMS))[INDEX[name]])
            chosen.append(name)
    if "misalignment" in fit:
        for (first, second, sign), pair in zip(PAIRS, PAIR_NAMES, strict=True):
            column = np.zeros(len(TERMS))
            column[INDEX[first]], column[INDEX[second]] = 0.5, 0.5 * sign
            columns.append(column)
            chosen.append(pair)
    # per-window variance of a magnitude from the per-axis noise, along the measured direction
    direction = y / np.linalg.norm(y, axis=1, keepdims=True)
    measured = noise is not None
    if not measured:
        axis_noise = np.where(np.isfinite(coarse.noise) & (coarse.noise > 0), coarse.noise, 1.0)
        noise = np.broadcast_to(axis_noise**2, y.shape)
    prior = np.sum(direction**2 * noise, axis=1)[:, None] * gravity**2

    def magnitude_model(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (0.5 * (gravity**2 - np.sum(inverse(theta, y) ** 2, axis=1)))[:, None], \
            magnitude_jacobian(theta, y)[:, None, :]

    return least_squares(coarse.theta, np.array(columns).T, chosen,
                         Observations(magnitude_model, samples, prior, measured), tolerance)


def magnitude_jacobian(theta: np.ndarray, y: np.ndarray) -> np.ndarray:
    """d(|f_hat|^2 / 2) / d theta (N, 18) with f_hat = K^-1 v, v + K_nl v^2 = y - b: the exact form of
    Eq. (16)'s regressors (q = K^-T f_hat ~ f_hat, d = 1 / (1 + 2 K_nl v) ~ 1, v ~ f_hat)."""
    f = inverse(theta, y)
    k = triad_matrix(theta)
    q = np.linalg.solve(k.T, f.T).T
    v = f @ k.T
    d = 1.0 / (1.0 + 2.0 * theta[NONLIN] * v)
    c = misalignment_matrix(theta[6:12])
    jac = np.zeros((len(y), len(TERMS)))
    jac[:, 0:3] = -q * d
    jac[:, 3:6] = -q * (f @ c.T)
    for j, (row, col, sign) in enumerate(MISALIGNMENT_ENTRIES):
        jac[:, 6 + j] = -q[:, row] * sign * (1.0 + theta[3 + row]) * f[:, col]
    jac[:, 12:15] = -q * d * v**2
    return jac


def _unit_basis(names: Sequence[str]) -> np.ndarray:
    return np.eye(len(TERMS))[:, [INDEX[n] for n in names]]


def _with_outer_reason(fit: Fit) -> Fit:
    sigma = fit.sigma.copy()
    sigma[INDEX["zero_offset_outer"]] = np.nan
    return replace(fit, sigma=sigma, unobservable={**fit.unobservable, "zero_offset_outer": OUTER_ZERO_REASON})
