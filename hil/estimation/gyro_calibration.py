"""Gyro calibration: bias against the earth rate at the dwell positions, scale factor and misalignment from
the rate plateaus, in one weighted least squares over all windows.

The model is the triad model of :mod:`hil.estimation.calibration_model` without a nonlinearity, with the
reference ``omega_ib^b = omega_nb^b + C_n^b omega_ie^n`` (the table's gimbal rates plus the earth rate at
the site latitude) averaged over each window's encoder angles. The middle and inner zero offsets are
held at the accelerometer calibration's values. The outer one, which gravity cannot see, turns the
earth rate's horizontal part in the body frame: the fit estimates it (relative to the configured table
azimuth) when the schedule separates it from the gyro terms.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hil.estimation.calibration_fit import Fit, Observations, full_scale_effects, least_squares
from hil.estimation.calibration_model import (
    INDEX,
    TERMS,
    Window,
    forward,
    forward_jacobian,
    measured_noise,
    window_means,
)
from hil.frames import Earth, TableGeometry

GYRO_GROUPS = ("bias", "scale", "misalignment", "zero_offset")
DEFAULT_TOLERANCE = 1e-6


def angular_rate_reference(windows: Sequence[Window], earth: Earth, geometry: TableGeometry,
                           zero_offsets: np.ndarray) -> np.ndarray:
    """omega_ib^b (rad/s) averaged over each window's encoder angles plus the zero offsets, (N, 3)."""
    def omega(angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
        c_bn, middle_inner, inner = geometry.attitude_matrix(angles)
        return geometry.body_rate_from(middle_inner, inner, rates) + earth.omega_n @ c_bn

    return window_means(windows, zero_offsets, omega)


def raw_rate_residuals(windows: Sequence[Window], earth: Earth, geometry: TableGeometry) -> np.ndarray:
    """(N, 3) rad/s: each window's angular rate minus the earth and gimbal rates at its encoder angles, the
    error-free model with zero offsets zero (the residual before calibration)."""
    y = np.array([w.angular_rate for w in windows])
    return y - angular_rate_reference(windows, earth, geometry, np.zeros(3))


def calibrate_gyros(windows: Sequence[Window], earth: Earth, geometry: TableGeometry,
                    zero_offsets: Sequence[float] = (0.0, 0.0, 0.0), zero_offset_covariance: np.ndarray | None = None,
                    fit: Sequence[str] = GYRO_GROUPS, tolerance: float = DEFAULT_TOLERANCE) -> Fit:
    """Bias, scale, misalignment (and the outer zero offset) over dwell and plateau windows; theta and sigma
    over :data:`TERMS` (nonlinearity held at zero), SI. ``zero_offsets`` (outer, middle, inner) rad: the
    accelerometer calibration's, NaN for one it could not observe (taken as zero), with their covariance
    (3, 3) rad^2, which enters the sigmas (the outer entry is ignored when the outer offset is fitted)."""
    if not any(not w.static for w in windows):
        raise ValueError("gyro calibration needs rate-plateau windows for the scale factors and misalignment")
    y = np.array([w.angular_rate for w in windows])
    samples = np.array([w.samples for w in windows], dtype=float)
    theta0 = np.zeros(len(TERMS))
    theta0[15:18] = np.nan_to_num(np.asarray(zero_offsets, dtype=float))

    def reference_at(zero: np.ndarray) -> np.ndarray:
        return angular_rate_reference(windows, earth, geometry, zero)

    def model(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        reference = reference_at(theta[15:18])
        return y - forward(theta, reference), forward_jacobian(theta, reference, reference_at)

    names = [t for t in TERMS if t.rsplit("_", 1)[0] in fit and not t.startswith("nonlinearity")
             and t not in ("zero_offset_middle", "zero_offset_inner")]
    basis = np.eye(len(TERMS))[:, [INDEX[n] for n in names]]
    held = np.zeros((len(TERMS), len(TERMS)))
    if zero_offset_covariance is not None:
        held[15:18, 15:18] = np.nan_to_num(zero_offset_covariance)
        if "zero_offset_outer" in names:
            held[15, :] = held[:, 15] = 0.0
    # each sample's variance, measured in its window
    noise = measured_noise([w.rate_noise for w in windows], y)
    observed = Observations(model, samples, noise if noise is not None else np.ones_like(y), noise is not None)
    return least_squares(theta0, basis, names, observed, tolerance, held_covariance=held,
                         effects=full_scale_effects(reference_at(theta0[15:18])))
