"""IEEE Std 952's five noise terms from Allan variances: one weighted non-negative fit and its intervals.

Model (IEEE Std 952-1997, Annex C, Eqs. C.8, C.11, C.15, C.17, C.20; Std 1293-1998 the same for
accelerometers), in the rate's unit (rad/s, m/s^2):

    avar(tau) = 3 Q^2 / tau^2  +  N^2 / tau  +  (2 ln 2 / pi) B^2  +  K^2 tau / 3  +  R^2 tau^2 / 2,

Q the quantisation noise (rad, m/s: an output quantised to q with its remainder carried has Q = q /
sqrt(12)), N the white rate (angle / velocity random walk), B the bias instability (the flat floor of the
deviation is 0.664 B), K the rate random walk, R the rate ramp (rad/s^2, m/s^3). In the power-law notation
of frequency metrology the rate is the "frequency": quantisation is white PM (alpha = 2), white rate white
FM (0), bias instability flicker FM (-1), random walk RW FM (-2); the ramp is deterministic.

The fit weights each estimate by its inverse standard deviation under the current model (``allan_cov``
with the ``products`` of the tau), iterated to a fixed point. The coefficients are G avar, G the weighted
pseudo-inverse of the active terms, so their covariance is G C G^T with C the full covariance of the
estimates under the fitted model: their correlation over neighbouring tau counted, not bounded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.estimation.allan_cov import avar_covariance

FLICKER_FLOOR = 2.0 * math.log(2.0) / math.pi  # avar floor / B^2 (IEEE 952 Eq. C.15); sqrt: 0.664
TERM_NAMES = ("quantization", "white", "bias_instability", "random_walk", "ramp")
WHITE = TERM_NAMES.index("white")
# Standard deviations a term's estimate must exceed to be resolved: quantization and the ramp, which most records
# hold none of, enter the fit only beyond 1.5 (docs/noise.md: at 1 a false ramp takes a random walk's longest
# tau, at 2 a true one is left out of short records and its slope biases the others)
RESOLVED_AT = np.array([1.5 if name in ("quantization", "ramp") else 1.0 for name in TERM_NAMES])
_MAX_ITERATIONS = 100
# An estimate's standard deviation is taken as at least this part of the model there (a record that is
# all ramp, whose estimates have no noise, would otherwise weigh infinitely).
_RELATIVE_SD_FLOOR = 1e-9
REASON_ZERO = "consistent with zero: its estimate is within {} of 0"
REASON_OUT = "out of the non-negative fit: the record holds none of it beside the other terms"
REASON_SILENT = "the record holds no noise"
REASON_REMOVED = "removed from the record before the analysis (noise.json detrend)"


@dataclass(frozen=True)
class Term:
    """One fitted coefficient and its two-sided interval; the value None, with the reason, when the fit
    cannot resolve it (the interval then its upper limit)."""

    value: float | None
    lower: float | None
    upper: float | None
    reason: str | None = None

    def scaled(self, unit: float) -> Term:
        """The same term in another unit: each figure divided by ``unit`` (SI per that unit)."""
        return Term(*(None if v is None else v / unit for v in (self.value, self.lower, self.upper)), self.reason)


@dataclass(frozen=True)
class TermFit:
    """The fitted coefficients of ``fit_terms``, their covariance, and the model they give; ``estimates`` and
    ``sd``, what each term is reported from: the fit's own, or for a term taken out by the elimination, the
    refit's with it back in beside the others."""

    coefficients: np.ndarray  # (5,): Q^2, N^2, B^2, K^2, R^2
    covariance: np.ndarray  # (5, 5)
    model: np.ndarray  # (M,) Allan variance of the fitted model
    parts: np.ndarray  # (M, 5): what each term contributes to it
    estimates: np.ndarray | None = None  # (5,), the coefficients where None
    sd: np.ndarray | None = None  # (5,), the covariance's where None

    def reported(self) -> tuple[np.ndarray, np.ndarray]:
        """(estimates, standard deviations) the terms are reported from."""
        estimates = self.coefficients if self.estimates is None else self.estimates
        return estimates, np.sqrt(np.diag(self.covariance)) if self.sd is None else self.sd


def design_matrix(tau: np.ndarray) -> np.ndarray:
    """(M, 5): the Allan variance per unit Q^2, N^2, B^2, K^2, R^2 at ``tau``."""
    return np.column_stack([3.0 / tau**2, 1.0 / tau, np.full_like(tau, FLICKER_FLOOR), tau / 3.0, tau**2 / 2.0])


def _root_weights(products: tuple[np.ndarray, np.ndarray], parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The estimates' covariance under the model ``parts`` and the inverse of their standard deviations."""
    full = avar_covariance(products, parts)
    sd = np.maximum(np.sqrt(np.clip(np.diag(full), 0.0, None)), _RELATIVE_SD_FLOOR * parts.sum(axis=1))
    return full, 1.0 / sd


def fit_terms(tau: np.ndarray, avar: np.ndarray, products: tuple[np.ndarray, np.ndarray],
              removed: tuple[str, ...] = ()) -> TermFit:
    """Weighted non-negative least-squares fit of the five-term model to avar (M,) (module docstring), then
    backward elimination: while quantization or the ramp is fitted within RESOLVED_AT standard deviations of
    zero, the less significant is taken out and the rest refitted, so that a term the record does not hold
    takes no share of its neighbours' tau. A term out of the fit keeps the standard deviation it would have
    were it in (its upper limit); the terms ``removed`` (names of TERM_NAMES: taken out of the record before)
    are never fitted."""
    design = design_matrix(tau)
    kept = np.array([name not in removed for name in TERM_NAMES])
    allowed = kept.copy()
    while True:
        fit = _fit(design, avar, products, allowed)
        sd = np.sqrt(np.diag(fit.covariance))
        weak = np.flatnonzero((fit.coefficients > 0.0) & (fit.coefficients <= RESOLVED_AT * sd) & (RESOLVED_AT > 1.0))
        if not weak.size:
            break
        allowed[weak[np.argmin(fit.coefficients[weak] / sd[weak])]] = False
    estimates, sd = fit.coefficients.copy(), sd.copy()
    for q in np.flatnonzero(kept & ~allowed):  # taken out: reported as it comes out back in beside the others
        back = allowed.copy()
        back[q] = True
        refit = _fit(design, avar, products, back)
        estimates[q], sd[q] = refit.coefficients[q], math.sqrt(refit.covariance[q, q])
    return TermFit(fit.coefficients, fit.covariance, fit.model, fit.parts, estimates, sd)


def _fit(design: np.ndarray, avar: np.ndarray, products: tuple[np.ndarray, np.ndarray], allowed: np.ndarray) -> TermFit:
    """The iteratively weighted non-negative fit of the ``allowed`` columns, and its covariance."""
    from scipy import optimize  # here, not with the module: 0.5 s of start-up for every trial's report

    terms = design.shape[1]
    coefficients = np.zeros(terms)
    if not np.any(avar > 0.0):
        return TermFit(coefficients, np.zeros((terms, terms)), np.zeros_like(avar), np.zeros_like(design))
    parts = np.zeros_like(design)
    parts[:, WHITE] = np.maximum(avar, avar[avar > 0.0].min())
    for _ in range(_MAX_ITERATIONS):
        root_w = _root_weights(products, parts)[1]
        new = np.zeros(terms)
        new[allowed] = optimize.nnls(design[:, allowed] * root_w[:, None], avar * root_w)[0]
        converged = np.allclose(new, coefficients, rtol=1e-10, atol=0.0)
        coefficients, parts = new, design * new
        if converged or not np.any(new > 0.0):
            break
    covariance = np.zeros((terms, terms))
    active = coefficients > 0.0
    if active.any():
        full, root_w = _root_weights(products, parts)
        pseudo_inverse = np.linalg.pinv(design[:, active] * root_w[:, None]) * root_w  # G
        covariance[np.ix_(active, active)] = pseudo_inverse @ full @ pseudo_inverse.T
        for q in np.flatnonzero(~active):  # a term out of the fit: its variance were it in, for its upper limit
            with_q = active.copy()
            with_q[q] = True
            g = np.linalg.pinv(design[:, with_q] * root_w[:, None]) * root_w
            row = int(np.count_nonzero(with_q[:q]))
            covariance[q, q] = (g @ full @ g.T)[row, row]
    return TermFit(coefficients, covariance, parts.sum(axis=1), parts)


def term(coefficient: float, sd: float, level: float, resolved_at: float = 1.0) -> Term:
    """sqrt(coefficient) and its interval at ``level``; the value None, with the reason, when the record
    cannot resolve it.

    The interval is the normal one, coefficient -/+ z sd (z the two-sided normal quantile of ``level``),
    cut at zero, then the square root: the coefficient is a weighted sum of many estimates with weights of
    both signs, not one chi-square variance (docs/noise.md). It is given also where the value is not:
    unresolved when coefficient <= resolved_at sd (consistent with zero), and then the interval is the upper limit a
    lab quotes; for a term out of the non-negative fit (coefficient 0), [0, sqrt(z sd)] with sd its
    standard deviation were it in. A record without noise (sd 0) has neither.
    """
    from scipy import stats  # here, not with the module: see fit_terms

    if not sd > 0.0:
        return Term(None, None, None, REASON_SILENT)
    z = float(stats.norm.ppf(0.5 + level / 2.0))
    lower, upper = (math.sqrt(max(v, 0.0)) for v in (coefficient - z * sd, coefficient + z * sd))
    if coefficient > resolved_at * sd:
        return Term(math.sqrt(coefficient), lower, upper)
    within = "one standard deviation" if resolved_at == 1.0 else f"{resolved_at:g} standard deviations"
    return Term(None, lower, upper, REASON_ZERO.format(within) if coefficient > 0.0 else REASON_OUT)
