"""The scale factor test's fit (IEEE Std 952's scale-factor test series): per gyro, the mean output of each
rate step against its input rate, both directions.

The model is y = b + K x + A |x|: two lines through one zero-rate bias b, of slopes K+ = K + A for positive
input and K- = K - A for negative, so the scale factor K is the mean of the two (the least-squares line's
slope when the rates are symmetric), the asymmetry (K+ - K-) / K = 2 A / K and the bias is not pulled by it.
The nonlinearity is the largest residual from this model, in ppm of the full-scale output K max|x|: what
neither the scale factor nor its asymmetry explains, on the scale a datasheet gives it (docs/ratetests.md says
why not of the fitted scale factor). Weighted least squares with each step's 1-sigma; the sigmas are the fit's
(the steps' own scatter, not rescaled by the residuals, so a nonlinearity does not inflate them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SIGMA_FLOOR = 1e-15  # rad/s: a step's sigma at least this (a noiseless emulated gyro)


@dataclass(frozen=True)
class RatePoint:
    """One rate step of one gyro: rates in rad/s."""

    commanded: float  # the table's demand (signed)
    input: float  # the encoder's rate over the window's whole turns plus the earth's about the rate axis, on the gyro
    output: float  # the gyro's mean rate over the window
    sigma: float  # 1-sigma of ``output`` (the samples' scatter over their number)
    saturated: str | None = None  # why the step is left out of the fit (the gyro at its range, samples flagged)


@dataclass(frozen=True)
class ScaleFactorFit:
    """The fit of one gyro (module docstring); ratios are fractions (1e-6 = 1 ppm), rates rad/s."""

    scale: float  # K
    scale_sigma: float
    bias: float
    bias_sigma: float
    asymmetry: float  # (K+ - K-) / K, signed
    asymmetry_sigma: float
    nonlinearity: float  # max |residual| / (K max |x|)
    nonlinearity_sigma: float  # a step's typical 1-sigma on the same scale: the floor the residuals lie within
    residuals: np.ndarray  # per point used, of full-scale output
    full_scale: float  # K max |x|


def fit_scale_factor(points: list[RatePoint]) -> ScaleFactorFit:
    """The fit of the points not saturated; ValueError with fewer than two of each sign."""
    used = [p for p in points if not p.saturated]
    x = np.array([p.input for p in used])
    if min(np.sum(x > 0), np.sum(x < 0)) < 2:
        raise ValueError(f"{len(used)} usable steps: the fit needs two of each direction")
    y = np.array([p.output for p in used])
    sigma = np.maximum([p.sigma for p in used], SIGMA_FLOOR)
    design = np.column_stack([np.ones_like(x), x, np.abs(x)])
    weighted = design / sigma[:, None]
    cov = np.linalg.inv(weighted.T @ weighted)
    theta = cov @ weighted.T @ (y / sigma)
    b, k, a = theta
    gradient = np.array([0.0, -2.0 * a / k**2, 2.0 / k])
    full_scale = abs(k) * float(np.max(np.abs(x)))
    residuals = (y - design @ theta) / full_scale
    return ScaleFactorFit(
        scale=float(k), scale_sigma=float(np.sqrt(cov[1, 1])), bias=float(b), bias_sigma=float(np.sqrt(cov[0, 0])),
        asymmetry=float(2.0 * a / k), asymmetry_sigma=float(np.sqrt(gradient @ cov @ gradient)),
        nonlinearity=float(np.max(np.abs(residuals))), nonlinearity_sigma=float(np.sqrt(np.mean(sigma**2)) / full_scale),
        residuals=residuals, full_scale=full_scale)
