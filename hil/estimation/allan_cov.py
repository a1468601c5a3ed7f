"""Covariance of overlapping Allan variance estimates at several tau, for a sum of the model's noises and a
rate ramp.

Greenhall and Riley's EDF sums the squared covariance of second differences at one tau; the same sum over
two tau gives the covariance of the estimates there, which the term fit needs (its estimates at
neighbouring tau share most of their samples). For Gaussian rates and the estimate a_i = mean_k z_i(k)^2
/ (2 tau_i^2) over M_i second differences z_i(k) = x_{k+2m_i} - 2 x_{k+m_i} + x_k,

    cov(a_i, a_j) = 2 / (M_i M_j) sum_l count_ij(l) g_ij(l)^2,

count_ij(l) the pairs (k, k + l) of the two sums, g_ij(l) = sum_q sqrt(A_qi A_qj) rho_qij(l) the
covariance of z_i(k) / (sqrt 2 tau_i) and z_j(k + l) / (sqrt 2 tau_j): A_qi the Allan variance noise q
contributes at tau_i, rho_qij its correlation, sum_ab c_a c_b R_q(l + b m_j - a m_i) normalised, c = (1,
-2, 1) and R_q the phase's generalised autocovariance in samples: sw(t; alpha_q + 2) of ``allan_edf`` (F
infinite) for the rate noises, and for white PM (quantisation) 1 at t = 0, else 0.

A rate ramp R adds the same d_i = R tau_i^2 to every z_i(k): a_i gains d_i^2 / (2 tau_i^2) (its A_ri) and
d_i zbar_i / tau_i^2, zbar_i the mean difference, so

    cov(a_i, a_j) += 4 sqrt(A_ri A_rj) / (M_i M_j) sum_l count_ij(l) g_ij(l).

g is smooth between the lags where an argument of R_q crosses 0 (and the count bends), which are the only
lags where white PM's is not 0: the sum over the integers of a piece is taken directly at its first lag
and where it is short, else as the integral over the rest of the piece (Gauss-Legendre; exact for white
and random walk, whose g is polynomial there, to O(1 / length^2) otherwise). White noises and random walk
correlate only while the two differences share samples; flicker is summed a further 2 max(m_i, m_j) lags
each side, where its correlation has fallen to 2.4 % of its peak (the square the sum takes, to 6e-4).
"""

from __future__ import annotations

import numpy as np

from hil.estimation.allan_edf import sw

MODEL_ALPHAS = (2, 0, -1, -2)  # the fitted model's noises: quantisation (white PM), white rate, flicker, walk

_C = np.array([1.0, -2.0, 1.0])
_DIRECT = 32  # pieces of up to this many lags are summed term by term
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(16)


def _raw(lags: np.ndarray, mi: int, mj: int) -> np.ndarray:
    """sum_ab c_a c_b R_q(l + b m_j - a m_i) at ``lags``, per noise: (3, len(lags))."""
    shifts = (np.arange(3)[None, :] * mj - np.arange(3)[:, None] * mi).ravel()  # (9,): b m_j - a m_i
    weights = np.outer(_C, _C).ravel()
    t = lags[None, :] + shifts[:, None]
    return np.stack([weights @ _autocovariance(t, alpha) for alpha in MODEL_ALPHAS])


def _autocovariance(t: np.ndarray, alpha: int) -> np.ndarray:
    """R_q(t), t in samples: white PM's 1 at t = 0, a rate noise's sw(t; alpha + 2)."""
    return (t == 0.0).astype(float) if alpha == 2 else sw(t, alpha + 2)


def _points(mi: int, mj: int, ci: int, cj: int) -> tuple[np.ndarray, np.ndarray]:
    """Lags and their weights (count, times the node weight where a piece is integrated) of the pair's sum."""
    tail = 2 * max(mi, mj)
    low, high = max(-2 * mj - tail, -ci + 1), min(2 * mi + tail, cj - 1)
    kinks = {a * mi - b * mj for a in range(3) for b in range(3)} | {0, cj - ci, low, high + 1}
    edges = np.array(sorted(k for k in kinks if low <= k <= high + 1))
    lags, weights = [], []
    for start, stop in zip(edges[:-1], edges[1:]):
        if stop - start <= _DIRECT:
            x, w = np.arange(start, stop, dtype=float), np.ones(stop - start)
        else:  # the first lag on its own, the rest as the integral over [start + 1/2, stop - 1/2]
            half = (stop - start - 1) / 2.0
            x = np.concatenate([[start], start + 0.5 + half * (1.0 + _NODES)])
            w = np.concatenate([[1.0], half * _WEIGHTS])
        lags.append(x)
        weights.append(w)
    x, w = np.concatenate(lags), np.concatenate(weights)
    count = np.clip(np.minimum(ci, cj - x) - np.maximum(0.0, -x), 0.0, None)
    return x, w * count


def noise_products(factors: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """E (K, K, Q, Q) and L (K, K, Q) for the Q noises ``MODEL_ALPHAS``: cov(a_i, a_j) = sum_qr sqrt(A_qi A_qj
    A_ri A_rj) E_ijqr, plus 4 sqrt(A_ri A_rj) sum_q sqrt(A_qi A_qj) L_ijq with a rate ramp.

    ``counts`` the second differences M_i at each factor (fewer than N - 2m where gaps left some out).
    """
    factors = [int(m) for m in factors]
    zero = [_raw(np.zeros(1), m, m)[:, 0] for m in factors]  # (Q,) variance scale of each noise at m
    noises = len(MODEL_ALPHAS)
    products = np.zeros((len(factors), len(factors), noises, noises))
    sums = np.zeros((len(factors), len(factors), noises))
    for i, mi in enumerate(factors):
        for j in range(i, len(factors)):
            mj = factors[j]
            x, w = _points(mi, mj, int(counts[i]), int(counts[j]))
            rho = _raw(x, mi, mj) / np.sqrt(zero[i] * zero[j])[:, None]
            products[i, j] = products[j, i] = 2.0 / (counts[i] * counts[j]) * (rho * w) @ rho.T
            sums[i, j] = sums[j, i] = rho @ w / (counts[i] * counts[j])
    return products, sums


def avar_covariance(products: tuple[np.ndarray, np.ndarray], parts: np.ndarray) -> np.ndarray:
    """(K, K) covariance of the Allan variance estimates where the noises contribute ``parts`` (K, Q + 1): the
    Q noises of ``MODEL_ALPHAS`` and last a rate ramp."""
    squared, sums = products
    root = np.sqrt(np.clip(parts, 0.0, None))
    noise, ramp = root[:, :-1], root[:, -1]
    return (np.einsum("iq,jq,ir,jr,ijqr->ij", noise, noise, noise, noise, squared)
            + 4.0 * np.outer(ramp, ramp) * np.einsum("iq,jq,ijq->ij", noise, noise, sums))
