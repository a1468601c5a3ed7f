"""The weighted least squares of the multi-position calibration over the terms of
:mod:`hil.estimation.calibration_model`.

A fit names the terms it estimates; the others stay at their given values. Observability is judged term by
term in priority order on the column-scaled design: a term whose column is, to within ``tolerance`` of its
squared norm, a combination of the columns already kept cannot be separated by the schedule; the reason names
them. Nor can a term too weakly excited (:func:`weakly_excited`). Either is held at zero, the fit repeated
without it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from hil.estimation.calibration_model import INDEX, MIS, NONLIN, SCALE, TERMS
from hil.units import ARCSEC, PPM, UG_PER_G2

# how a term judged by its excitation is named in its reason: unit label, SI per unit
REPORT_UNITS = {"scale": ("ppm", PPM), "misalignment": ("arcsec", ARCSEC), "nonlinearity": ("ug/g^2", UG_PER_G2)}


@dataclass(frozen=True)
class Fit:
    """A least-squares solution: theta (18,), its covariance over the fitted terms, what was left out.

    ``sigma`` (18,) is the 1-sigma of every term (0 for terms held fixed, NaN for unobservable ones);
    ``unobservable`` maps a term to the reason; ``noise`` is the per-group residual standard deviation
    of one sample (noise variance from the residuals); ``residuals`` as the observation (N, groups).
    """

    theta: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray
    fitted: tuple[str, ...]
    unobservable: dict[str, str] = field(default_factory=dict)
    noise: np.ndarray = field(default_factory=lambda: np.zeros(0))
    residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))


def select_terms(design: np.ndarray, names: Sequence[str], tolerance: float) -> tuple[list[int], dict[str, str]]:
    """Columns kept (in the given priority order) and the reasons for those left out.

    A column is left out when the part of it (scaled to unit norm) not explained by the kept columns
    has squared norm below ``tolerance``: the schedule cannot separate that term.
    """
    kept: list[int] = []
    reasons: dict[str, str] = {}
    norms = np.linalg.norm(design, axis=0)
    for j, name in enumerate(names):
        if norms[j] == 0.0:
            reasons[name] = "does not change the measurements of this schedule (its design column is zero)"
            continue
        col = design[:, j] / norms[j]
        if kept:
            basis = design[:, kept] / norms[kept]
            coef = np.linalg.lstsq(basis, col, rcond=None)[0]
            unexplained = float(np.sum((col - basis @ coef) ** 2))
        else:
            coef, unexplained = np.zeros(0), 1.0
        if unexplained < tolerance:
            big = np.abs(coef) > 0.05 * np.max(np.abs(coef))
            partners = ", ".join(names[kept[k]] for k in np.flatnonzero(big))
            reasons[name] = (f"not separable from {partners} in this schedule (design rank "
                             f"{np.linalg.matrix_rank(design[:, kept]) } with it added; unexplained "
                             f"fraction {unexplained:.1e} < {tolerance:g})")
        else:
            kept.append(j)
    return kept, reasons


def full_scale_effects(reference: np.ndarray) -> np.ndarray:
    """Per term (18,), the size of its effect per unit at the schedule's full scale R, the largest reference
    magnitude of its windows (g, or the largest rate): R for scale and misalignment, R^2 for the nonlinearity,
    0 (not judged by excitation) for the bias and the zero offsets, which act on what the schedule spans."""
    top = float(np.max(np.linalg.norm(reference, axis=1)))
    effects = np.zeros(len(TERMS))
    effects[SCALE] = effects[MIS] = top
    effects[NONLIN] = top**2
    return effects


@dataclass(frozen=True)
class Observations:
    """What a fit is fitted to. ``model(theta)`` gives the residuals (N, G) (observation minus prediction) and the
    Jacobian of the prediction (N, G, 18); column g of the residuals belongs to noise group g. A window's weight is
    ``samples / (prior * s_g^2)``: ``samples`` (N,) its samples, ``prior`` (N, G) the relative per-sample variance,
    s_g^2 the group's variance factor from the residuals (dof from the leverages), re-estimated each iteration.
    ``measured``: ``prior`` is each sample's variance as measured inside the windows; s_g^2 then only inflates it
    (residuals larger than that noise explains: an error the model lacks), never shrinks it."""

    model: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    samples: np.ndarray
    prior: np.ndarray
    measured: bool = False


def least_squares(theta0: np.ndarray, basis: np.ndarray, names: Sequence[str], observed: Observations,
                  tolerance: float, iterations: int = 8, held_covariance: np.ndarray | None = None,
                  effects: np.ndarray | None = None) -> Fit:
    """Weighted Gauss-Newton over the coordinates ``basis`` (18, p) of theta, named ``names``, of the
    ``observed`` windows (:class:`Observations`).

    A factor from the residuals alone rests on few degrees of freedom (18 windows, some 16 terms): the
    errors over sigmas it gives follow Student's t with about a dozen, whose tails are far heavier than the
    normal's. ``held_covariance`` (18, 18): the covariance of terms held at values estimated elsewhere (zero
    for the others), carried into the fitted terms through the Jacobian.

    Terms the schedule cannot observe are left out, held at zero (uncompensated) with NaN sigma and the
    reason: first by rank (:func:`select_terms`), then, with ``effects`` (:func:`full_scale_effects`), by
    excitation (:func:`weakly_excited`), the fit repeated without them.
    """
    theta0 = np.array(theta0, dtype=float)
    residual, jac = observed.model(theta0)
    design = (jac @ basis) * np.sqrt(observed.samples[:, None, None] / observed.prior[:, :, None])
    kept, unobservable = select_terms(design.reshape(-1, basis.shape[1]), names, tolerance)
    while True:
        theta0[[INDEX[n] for n in unobservable if n in INDEX]] = 0.0
        solution = _solve(theta0, basis[:, kept], observed, iterations)
        weak = {} if effects is None else weakly_excited(solution, [names[k] for k in kept], effects, tolerance)
        if not weak:
            break
        unobservable.update(weak)
        kept = [k for k in kept if names[k] not in weak]
    return solution.fit(unobservable, held_covariance, observed.prior)


@dataclass(frozen=True)
class _Solution:
    """A Gauss-Newton solution over ``basis``: theta, the residuals and Jacobian there, the variance factors, the
    final weights (N * G,), the fit's own covariance over the basis coordinates, the inverse normal matrix."""

    theta: np.ndarray
    residual: np.ndarray
    jac: np.ndarray
    basis: np.ndarray
    factor: np.ndarray
    weights: np.ndarray
    cov_fit: np.ndarray
    root: np.ndarray

    def own_sigma(self) -> np.ndarray:
        """1-sigma (18,) of the fitted terms from the fit alone (no held covariance carried in)."""
        return np.sqrt(np.maximum(np.diag(self.basis @ self.cov_fit @ self.basis.T), 0.0))

    def fit(self, unobservable: dict[str, str], held_covariance: np.ndarray | None, prior: np.ndarray) -> Fit:
        """The :class:`Fit`, with the covariance of held terms carried in."""
        basis = self.basis
        covariance = basis @ self.cov_fit @ basis.T
        if held_covariance is not None:
            h = (self.jac @ basis).reshape(-1, basis.shape[1])
            carry = basis @ (-self.root @ h.T @ (self.weights[:, None] * self.jac.reshape(-1, len(TERMS)))) \
                + np.eye(len(TERMS))
            covariance = covariance + carry @ held_covariance @ carry.T
        sigma = np.sqrt(np.maximum(np.diag(covariance), 0.0))
        for name in unobservable:
            if name in INDEX:
                sigma[INDEX[name]] = np.nan
        fitted = tuple(TERMS[k] for k in np.flatnonzero(np.any(basis != 0, axis=1)))
        noise = np.sqrt(self.factor * np.mean(prior, axis=0))
        return Fit(self.theta, sigma, covariance, fitted, unobservable, noise, self.residual)


def _solve(theta0: np.ndarray, basis: np.ndarray, observed: Observations, iterations: int) -> _Solution:
    """Gauss-Newton from theta0 over ``basis`` (see :func:`least_squares`)."""
    model, samples, prior, measured = observed.model, observed.samples, observed.prior, observed.measured
    theta = np.array(theta0, dtype=float)
    residual, jac = model(theta)
    factor = np.ones(residual.shape[1])

    def usable(f: np.ndarray) -> np.ndarray:
        return np.maximum(_usable(f), 1.0) if measured else _usable(f)

    for _ in range(iterations):
        h = (jac @ basis).reshape(-1, basis.shape[1])
        w = (samples[:, None] / (prior * usable(factor))).reshape(-1)
        step = np.linalg.solve(h.T @ (w[:, None] * h), h.T @ (w * residual.reshape(-1)))
        theta = theta + basis @ step
        residual, jac = model(theta)
        factor = _variance_factors(residual, jac @ basis, samples[:, None] / prior, usable(factor))
        if np.max(np.abs(step)) < 1e-15:
            break
    h = (jac @ basis).reshape(-1, basis.shape[1])
    w = (samples[:, None] / (prior * usable(factor))).reshape(-1)
    # sandwich form: a group whose residuals are zero (noise-free data) gets zero variance
    ratio = np.broadcast_to(1.0 if measured else factor / usable(factor), (len(samples), len(factor))).reshape(-1)
    root = np.linalg.inv(h.T @ (w[:, None] * h))
    cov_fit = root @ (h.T @ ((w * ratio)[:, None] * h)) @ root
    return _Solution(theta, residual, jac, basis, factor, w, cov_fit, root)


def weakly_excited(solution: _Solution, names: Sequence[str], effects: np.ndarray, tolerance: float) -> dict[str, str]:
    """The fitted terms the schedule excites too weakly to observe, with the reason.

    A term's own 1-sigma (without held covariance) times ``effects`` (its effect at the schedule's full scale,
    :func:`full_scale_effects`) is compared with the resolution of the outputs it acts on, ``1 / sqrt(sum w)``: the
    1-sigma of a constant fitted alone to them. Beyond ``1 / sqrt(tolerance)`` times that, the term's
    information is below ``tolerance`` of a fully excited term's: the physically scaled normal matrix is
    rank-deficient there, however independent the term's column looks scaled to its own norm (a scale factor
    seen only through the earth's rate).
    """
    sigma = solution.own_sigma()
    weights = solution.weights.reshape(solution.jac.shape[:2])
    limit = 1.0 / math.sqrt(tolerance)
    reasons = {}
    for name in names:
        k = INDEX.get(name)
        if k is None or effects[k] <= 0.0:
            continue
        touched = np.any(solution.jac[:, :, k] != 0.0, axis=0)
        ratio = sigma[k] * effects[k] * math.sqrt(float(np.sum(weights[:, touched])))
        if ratio > limit:
            label, unit = REPORT_UNITS[name.rsplit("_", 1)[0]]
            reasons[name] = (f"too weakly excited by this schedule (estimate {solution.theta[k] / unit:.4g} +- "
                             f"{sigma[k] / unit:.2g} {label}, not applied): its 1-sigma effect at the schedule's full "
                             f"scale is {ratio:.3g} times the 1-sigma of a constant fitted to the same outputs (limit "
                             f"{limit:.3g} = 1/sqrt(calibration.rank_tolerance))")
    return reasons


def _usable(factor: np.ndarray) -> np.ndarray:
    """Variance factors fit to weight with: unknown (NaN) as 1, zero as a tiny fraction of the largest."""
    finite = np.where(np.isfinite(factor), factor, 1.0)
    top = np.max(finite)
    return np.maximum(finite, 1e-30 * top if top > 0 else 1.0)


def _variance_factors(residual: np.ndarray, jac: np.ndarray, base_weight: np.ndarray,
                      factor: np.ndarray) -> np.ndarray:
    """s_g^2 per group: weighted residual sum over (rows - leverage), the unbiased a-posteriori variance;
    NaN for a group without degrees of freedom. ``base_weight`` is samples / prior, (N, G)."""
    n, groups, p = jac.shape
    h = jac.reshape(-1, p)
    w = (base_weight / factor).reshape(-1)
    leverage = (np.einsum("ij,jk,ik->i", h, np.linalg.inv(h.T @ (w[:, None] * h)), h) * w).reshape(n, groups)
    dof = n - leverage.sum(axis=0)
    ssr = np.sum(base_weight * residual**2, axis=0)
    return np.where(dof > 0.5, ssr / np.maximum(dof, 0.5), np.nan)
