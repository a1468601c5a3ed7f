"""The frequency response test's fits: the gyro against the encoder's rate at each frequency (a sine fit), and
the response as a second-order low-pass with a pure delay.

At each frequency f both rates (the gyro's increments and the encoder's turns, each over the same IMU intervals,
so that the averaging over an interval cancels in their ratio) are fitted with a cos, a sin and a constant by
least squares; the ratio R of their phasors is the response, its relative 1-sigma s from the residuals'
scatter (sqrt(2 / N) of it on a phasor's component), so gain (dB) has 20 / ln 10 s and phase (rad) s.

The model H(f) = fn^2 / (fn^2 - f^2 + 2 j zeta fn f) e^{-j 2 pi f tau} is fitted to the complex ratios, each
weighted by its sigma (so no phase needs unwrapping), over (ln fn, zeta, tau) by nonlinear least squares from
a start read off the data (fn where the gain crosses -3 dB, tau from the phase below it); the covariance is
the inverse of J^T J. The -3 dB bandwidth is fn sqrt(1 - 2 zeta^2 + sqrt((1 - 2 zeta^2)^2 + 1)), its sigma
through its gradient; a bandwidth above the highest frequency tested is reported as beyond it (None): the band
then shows the low-pass's onset alone, which neither fixes its damping nor keeps it apart from the delay.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DB = 20.0 / math.log(10.0)  # dB per neper


def phasor(t: np.ndarray, x: np.ndarray, f: float) -> tuple[complex, float]:
    """x's complex amplitude at f (x ~ Re(P e^{j 2 pi f t}) + c) and the 1-sigma of its real and imaginary parts."""
    w = 2.0 * math.pi * f * (t - t[0])
    design = np.column_stack([np.cos(w), np.sin(w), np.ones_like(w)])
    coef, *_ = np.linalg.lstsq(design, x, rcond=None)
    residual = x - design @ coef
    spread = float(np.sqrt(np.sum(residual**2) / max(len(x) - 3, 1)))
    return complex(coef[0], -coef[1]), spread * math.sqrt(2.0 / len(x))


def response_at(t: np.ndarray, gyro: np.ndarray, table: np.ndarray, f: float) -> tuple[complex, float]:
    """The ratio of the gyro's phasor to the table's at f and its relative 1-sigma."""
    g, g_sigma = phasor(t, gyro, f)
    e, e_sigma = phasor(t, table, f)
    return g / e, math.hypot(g_sigma / abs(g), e_sigma / abs(e))


def bandwidth_of(fn: float, zeta: float) -> float:
    """The -3 dB frequency of the second-order low-pass."""
    c = 1.0 - 2.0 * zeta**2
    return fn * math.sqrt(c + math.sqrt(c * c + 1.0))


def model(f: np.ndarray, fn: float, zeta: float, tau: float) -> np.ndarray:
    """H(f) of the module docstring."""
    return fn**2 / (fn**2 - f**2 + 2j * zeta * fn * f) * np.exp(-2j * math.pi * f * tau)


@dataclass(frozen=True)
class ResponseFit:
    """The fitted low-pass and delay (Hz, -, s) with their 1-sigmas; ``bandwidth`` None when above ``f_max``."""

    natural: float
    damping: float
    damping_sigma: float
    delay: float
    delay_sigma: float
    bandwidth: float | None
    bandwidth_sigma: float | None
    f_max: float


def _start(f: np.ndarray, ratio: np.ndarray) -> tuple[float, float, float]:
    """(ln fn, zeta, tau) to start from: fn where the gain first falls below -3 dB (else twice the highest
    frequency), zeta 0.7, tau from the phase left after that low-pass, at the frequencies below fn."""
    below = np.flatnonzero(np.abs(ratio) < 1.0 / math.sqrt(2.0))
    fn = float(f[below[0]]) if len(below) else 2.0 * float(f[-1])
    rest = np.unwrap(np.angle(ratio / model(f, fn, 0.7, 0.0)))
    low = f <= fn
    tau = float(-np.sum(rest[low] * f[low]) / (2.0 * math.pi * np.sum(f[low] ** 2)))
    return math.log(fn), 0.7, tau


def fit_response(f: np.ndarray, ratio: np.ndarray, sigma: np.ndarray) -> ResponseFit:
    """The model fitted to the ratios (relative 1-sigmas ``sigma``) at frequencies f (Hz), ascending."""
    from scipy.optimize import least_squares  # with the fit only

    f, ratio = np.asarray(f, dtype=float), np.asarray(ratio)
    weight = 1.0 / (np.abs(ratio) * np.asarray(sigma))

    def residuals(p: np.ndarray) -> np.ndarray:
        d = (ratio - model(f, math.exp(p[0]), p[1], p[2])) * weight
        return np.concatenate([d.real, d.imag])

    solution = least_squares(residuals, _start(f, ratio), bounds=([-np.inf, 0.05, -np.inf], [np.inf, 5.0, np.inf]),
                             x_scale="jac")
    cov = np.linalg.pinv(solution.jac.T @ solution.jac)
    log_fn, zeta, tau = solution.x
    fn = math.exp(log_fn)
    bandwidth = bandwidth_of(fn, zeta)
    step = 1e-6
    gradient = np.array([bandwidth,  # d/d ln fn
                         (bandwidth_of(fn, zeta + step) - bandwidth_of(fn, zeta - step)) / (2.0 * step), 0.0])
    beyond = bandwidth > f[-1]
    return ResponseFit(fn, float(zeta), float(math.sqrt(cov[1, 1])), float(tau), float(math.sqrt(cov[2, 2])),
                       None if beyond else bandwidth,
                       None if beyond else float(math.sqrt(gradient @ cov @ gradient)), float(f[-1]))
