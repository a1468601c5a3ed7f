"""Calibration terms over temperature: each term a polynomial in the IMU's temperature, fitted across the
calibrations at several temperatures, and applied at each sample's own temperature.

A term's value at the K temperatures T_k (its estimate v_k with sigma s_k, from the multi-position calibration
there) gives, with dT = T - reference_c, the polynomial ``p(dT) = c_0 + c_1 dT + ... + c_n dT^n`` by weighted least
squares (weights 1 / s_k^2); its coefficients' covariance is the normal matrix's inverse, inflated by the
residuals' chi-square per degree of freedom where that exceeds 1 (a temperature dependence the order does not
hold), never shrunk. n + 1 <= K: an order the temperatures cannot support is refused before the trial.

Applied, the 18 terms of a triad (:data:`hil.estimation.calibration_model.TERMS`) at temperature T are the
calibration's (the polynomials' constant terms) plus ``sum_j c_j dT^j`` (j >= 1) of the terms with a polynomial;
the inverse of the forward model then runs sample by sample (:func:`compensate_each`).
"""

from __future__ import annotations

import numpy as np

from hil.estimation.calibration_model import BIAS, MIS, MISALIGNMENT_ENTRIES, NONLIN, SCALE

SIGMA_FLOOR = 1e-150  # a noise-free estimate's zero sigma, as a weight whose square stays finite


def polynomial_fit(temperature_c: np.ndarray, values: np.ndarray, sigmas: np.ndarray, order: int,
                   reference_c: float) -> tuple[np.ndarray, np.ndarray]:
    """(coefficients (order + 1,), their covariance) of the polynomial in T - reference_c through ``values`` (K,)
    with 1-sigma ``sigmas`` (K,) at the temperatures (K,), lowest order first (module docstring)."""
    design = np.vander(np.asarray(temperature_c, float) - reference_c, order + 1, increasing=True)
    weights = 1.0 / np.maximum(np.asarray(sigmas, float), SIGMA_FLOOR) ** 2
    covariance = np.linalg.inv(design.T @ (weights[:, None] * design))
    coefficients = covariance @ design.T @ (weights * values)
    dof = len(values) - (order + 1)
    if dof > 0:
        chi2 = float(np.sum(weights * (values - design @ coefficients) ** 2))
        covariance = covariance * max(1.0, chi2 / dof)
    return coefficients, covariance


def fit_polynomial(temperature_c: np.ndarray, values: np.ndarray, sigmas: np.ndarray, order: int,
                   reference_c: float) -> tuple[np.ndarray, np.ndarray]:
    """(coefficients, their 1-sigma) of :func:`polynomial_fit`."""
    coefficients, covariance = polynomial_fit(temperature_c, values, sigmas, order, reference_c)
    return coefficients, np.sqrt(np.maximum(np.diag(covariance), 0.0))


def polynomial_at(coefficients: np.ndarray, covariance: np.ndarray, reference_c: float,
                  at_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The polynomial's value and 1-sigma at the temperatures ``at_c`` (M,) deg C."""
    powers = np.vander(np.asarray(at_c, float) - reference_c, len(coefficients), increasing=True)
    return powers @ coefficients, np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", powers, covariance, powers), 0.0))


class ThermalTerms:
    """The temperature part of one triad's terms: ``slopes`` (n, 18) SI per deg C^j, row j - 1 the coefficient
    of dT^j (zero for a term without a polynomial), about ``reference_c``."""

    def __init__(self, reference_c: float, slopes: np.ndarray) -> None:
        self.reference_c, self.slopes = reference_c, np.asarray(slopes, float)

    def thetas(self, theta: np.ndarray, temperature_c: np.ndarray) -> np.ndarray:
        """The terms (N, 18) at each temperature (N,) deg C, from the calibration's ``theta`` (18,); a sample
        without a temperature (NaN) gets ``theta``."""
        d = np.nan_to_num(np.asarray(temperature_c, float) - self.reference_c)
        powers = d[:, None] ** np.arange(1, len(self.slopes) + 1)
        return theta + powers @ self.slopes


def inverse_each(theta: np.ndarray, output: np.ndarray) -> np.ndarray:
    """References r (N, 3) from outputs y (N, 3), each through its own terms ``theta`` (N, 18): the inverse of
    :func:`hil.estimation.calibration_model.forward` sample by sample."""
    a = output - theta[:, BIAS]
    k = theta[:, NONLIN]
    v = 2.0 * a / (1.0 + np.sqrt(1.0 + 4.0 * k * a))
    c = np.broadcast_to(np.eye(3), (len(theta), 3, 3)).copy()
    for m, (row, col, sign) in enumerate(MISALIGNMENT_ENTRIES):
        c[:, row, col] = sign * theta[:, MIS.start + m]
    triad = (1.0 + theta[:, SCALE])[:, :, None] * c
    return np.linalg.solve(triad, v[:, :, None])[:, :, 0]


def compensate_each(accel: np.ndarray, gyro: np.ndarray, dtheta: np.ndarray, dv: np.ndarray,
                    dt: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Raw increments (N, 3) over intervals dt (s) -> compensated ones, each sample through its own terms
    ``accel`` and ``gyro`` (N, 18)."""
    dt = np.reshape(np.asarray(dt, dtype=float), (-1, 1))
    return inverse_each(gyro, np.asarray(dtheta) / dt) * dt, inverse_each(accel, np.asarray(dv) / dt) * dt
