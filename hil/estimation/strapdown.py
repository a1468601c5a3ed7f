"""Strapdown attitude in the initial-body inertial frame and the apparent acceleration there.

Within each sample interval the angular rate and specific force are taken as the quadratics whose
integrals match the last three increments (exact for motion that is quadratic over 3 samples; the
constant-rate case where history is missing or uneven). From them:

- attitude (2019 eq. 5, discretised): ``C_k = C_{k-1} exp(phi_k)`` with the rotation vector to second
  order, ``phi = alpha(h) + 1/2 int alpha x omega`` (Bortz), which with the quadratic rate is
  ``dtheta + (A x B + A x C) / 12 + B x C / 60`` for the scaled coefficients A, B, C below;
- velocity increment in i_b0 (2019 eq. 4 in increment form):
  ``dv^ib0_k = C_{k-1} int exp([alpha(tau) x]) f(tau) dtau`` by 3-node Gauss-Legendre quadrature, which
  carries rotation and sculling compensation to the order the quadratic allows;
- the interval mean of C_b^ib0 (the bias regressor of 2019 eq. 14), by the same quadrature.

The batch path is component-major: vectors (3, N), matrices (3, 3, N). Each step is then an
elementwise product of contiguous rows or an einsum along the samples, about a third of the cost of
stacked (N, 3, 3) matrix products, which numpy runs one small matrix at a time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(3)
NODES = 0.5 * (_NODES + 1.0)  # on [0, 1]
WEIGHTS = 0.5 * _WEIGHTS
# At the nodes s, the quadratic coefficients (A, B, C) of quadratic_coefficients give the integral
# A s + B s^2/2 + C s^3/3 (the rotation vector) and the rate A + B s + C s^2: (node, coefficient) matrices.
NODE_ANGLE = np.column_stack((NODES, NODES**2 / 2.0, NODES**3 / 3.0))
NODE_RATE = np.column_stack((np.ones(3), NODES, NODES**2))


@dataclass(frozen=True)
class StrapdownStep:
    """What one batch of increments gives, per sample, component-major."""

    c_end: np.ndarray  # (3, 3, N) C_b^ib0 at the end of each interval
    c_mean: np.ndarray  # (3, 3, N) mean of C_b^ib0 over each interval
    dv_ib0: np.ndarray  # (3, N) velocity increment resolved in i_b0


def product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a[..., n] @ b[..., n]`` for (3, 3, N) matrices (either may be one (3, 3) matrix)."""
    return np.einsum("ik...,kj...->ij...", a, b)


def cumulative_product(steps: np.ndarray) -> np.ndarray:
    """Prefix products ``steps[..., 0] @ ... @ steps[..., k]`` of (3, 3, N) matrices; work-efficient scan
    (~2N products)."""
    n = steps.shape[-1]
    if n == 1:
        return steps.copy()
    pair_prefix = cumulative_product(product(steps[..., 0 : n - 1 : 2], steps[..., 1:n:2]))  # (0,1), (2,3), ...
    out = np.empty_like(steps)
    out[..., 0] = steps[..., 0]
    out[..., 1:n:2] = pair_prefix
    out[..., 2:n:2] = product(pair_prefix[..., : (n - 1) // 2], steps[..., 2:n:2])
    return out


SERIES_LIMIT = 1e-2  # rad^2: below, the factors' series to a^8 are exact to rounding (the next terms are < 3e-18)


def rodrigues_factors(rotvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``sin(a)/a`` and ``(1 - cos a)/a^2`` of (3, ...) rotation vectors of angle a.

    Their Taylor series in ``a^2`` to the a^8 term where ``a^2 < SERIES_LIMIT`` (a sample's rotation, far
    below 0.1 rad), ``np.sinc`` elsewhere: no square root, no sine for the common case, no loss at small a.
    """
    a2 = rotvec[0] * rotvec[0] + rotvec[1] * rotvec[1] + rotvec[2] * rotvec[2]
    sin_a = 1.0 + a2 * (-1.0 / 6.0 + a2 * (1.0 / 120.0 + a2 * (-1.0 / 5040.0 + a2 / 362880.0)))
    cos_a = 0.5 + a2 * (-1.0 / 24.0 + a2 * (1.0 / 720.0 + a2 * (-1.0 / 40320.0 + a2 / 3628800.0)))
    large = a2 >= SERIES_LIMIT
    if large.any():
        angle = np.sqrt(a2[large])
        sin_a[large], cos_a[large] = np.sinc(angle / np.pi), 0.5 * np.sinc(angle / (2.0 * np.pi)) ** 2
    return sin_a, cos_a


def rotation_matrices(rotvec: np.ndarray, factors: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """exp([phi x]) for (3, N) rotation vectors (Rodrigues), (3, 3, N); ``factors`` their
    :func:`rodrigues_factors` when already formed.

    ``I + sin(a)/a K + (1 - cos a)/a^2 K^2`` with ``K^2 = phi phi^T - a^2 I`` written out element by
    element; equal to scipy's ``Rotation.from_rotvec(...).as_matrix()`` to rounding at a few
    microseconds per call where scipy's input handling costs ~100 us for small batches.
    """
    a, b = factors or rodrigues_factors(rotvec)
    x, y, z = rotvec
    ax, ay, az = a * x, a * y, a * z
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    xx, yy, zz = x * x, y * y, z * z
    return np.array([[1.0 - b * (yy + zz), bxy - az, bxz + ay],
                     [bxy + az, 1.0 - b * (xx + zz), byz - ax],
                     [bxz - ay, byz + ax, 1.0 - b * (xx + yy)]])


def rotate(rotvec: np.ndarray, v: np.ndarray, factors: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """exp([phi x]) v for (3, ...) rotation vectors and vectors,
    ``v + sin(a)/a phi x v + (1 - cos a)/a^2 phi x (phi x v)``; ``factors`` as for :func:`rotation_matrices`."""
    a, b = factors or rodrigues_factors(rotvec)
    pv = cross(rotvec, v)
    return v + a * pv + b * cross(rotvec, pv)


def mean_rotation(vectors: np.ndarray, sin_a: np.ndarray, cos_a: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``sum_k w_k exp([phi_k x])`` for (3, K, N) rotation vectors with their (K, N) :func:`rodrigues_factors`,
    (3, 3, N), without forming the K rotations: with ``K^2 = phi phi^T - a^2 I`` the sum is
    ``(sum w - tr M) I + [(sum_k w_k sin_a_k phi_k) x] + M``, ``M = sum_k w_k cos_a_k phi_k phi_k^T``."""
    weights = weights[:, None]
    m = np.einsum("ikn,jkn->ijn", vectors * (cos_a * weights), vectors)
    axial = np.einsum("kn,ikn->in", sin_a * weights, vectors)
    diagonal = weights.sum() - (m[0, 0] + m[1, 1] + m[2, 2])
    for i in range(3):
        m[i, i] += diagonal
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):  # [u x] has -u_k at (i, j) and +u_k at (j, i)
        m[i, j] -= axial[k]
        m[j, i] += axial[k]
    return m


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cross product of (3, ...) arrays along their first axis."""
    return np.array((u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]))


def orthonormalised(c: np.ndarray) -> np.ndarray:
    """One Newton step towards the nearest rotation, ``1.5 C - 0.5 C C^T C``: removes the rounding a
    product of rotations accumulates (quadratic convergence; the error here is ~1e-16)."""
    return 1.5 * c - 0.5 * c @ c.T @ c


def quadratic_coefficients(x: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C) with ``integral over the current interval up to s = A s + B s^2/2 + C s^3/3`` (s in [0, 1]).

    The rate ``(A + B s + C s^2) / h`` integrates to x over the current interval, x1 over the one
    before and x2 over the one before that.
    """
    b = x - x1
    c = 0.5 * (x - 2.0 * x1 + x2)
    return x - 0.5 * b - c / 3.0, b, c


class Strapdown:
    """C_b^ib0 from gyro increments; starts at identity (i_b0 is the body at the first sample's start)."""

    def __init__(self) -> None:
        self.attitude = np.eye(3)
        self._history: tuple[np.ndarray, np.ndarray] | None = None  # last 2 ([dtheta dv] (2, 6), dt)

    def carry(self, rotation: np.ndarray) -> None:
        """Jump the attitude by a known body rotation ``C_b(end)^b(start)`` over a gap in the increments;
        the rate history restarts after it."""
        self.attitude = orthonormalised(self.attitude @ rotation)
        self._history = None

    def update_many(self, dtheta: np.ndarray, dv: np.ndarray, dt: np.ndarray) -> StrapdownStep:
        """Advance over N consecutive increments (N, 3) with interval lengths dt (N,)."""
        x = np.concatenate((dtheta.T, dv.T))  # (6, N): both sensors' increments, each step below one numpy call
        if self._history is None:  # no history: constant rate over the first intervals
            self._history = (np.repeat(x[:, :1], 2, axis=1), np.full(2, dt[0]))
        x_all = np.concatenate((self._history[0], x), axis=1)
        dt_all = np.concatenate((self._history[1], dt))
        even = (np.abs(dt_all[1:-1] - dt) <= 1e-3 * dt) & (np.abs(dt_all[:-2] - dt) <= 1e-3 * dt)
        a, b, c = quadratic_coefficients(x, x_all[:, 1:-1], x_all[:, :-2])
        if not even.all():  # uneven history: drop to the constant-rate case
            a, b, c = np.where(even, a, x), b * even, c * even
        a_th, b_th, c_th = a[:3], b[:3], c[:3]

        phi = x[:3] + cross(a_th, b_th + c_th) / 12.0 + cross(b_th, c_th) / 60.0
        coefficients = np.array((a, b, c))  # (3 coefficients, 6, N)
        # (3, 3 nodes, N): the rotation vector at each node, and the specific force there times h
        alpha = np.einsum("ji,ikn->kjn", NODE_ANGLE, coefficients[:, :3])
        force = np.einsum("ji,ikn->kjn", NODE_RATE, coefficients[:, 3:])
        sin_a, cos_a = rodrigues_factors(np.concatenate((phi[:, None], alpha), axis=1))  # step and node factors
        c_end = product(self.attitude, cumulative_product(rotation_matrices(phi, (sin_a[0], cos_a[0]))))
        c_start = np.concatenate((self.attitude[..., None], c_end[..., :-1]), axis=2)
        node_factors = (sin_a[1:], cos_a[1:])
        dv_body = np.einsum("ikn,k->in", rotate(alpha, force, node_factors), WEIGHTS)
        r_mean = mean_rotation(alpha, *node_factors, WEIGHTS)

        # Re-orthonormalise the carried attitude so rounding cannot build up over a long trial.
        self.attitude = orthonormalised(c_end[..., -1])
        self._history = (x_all[:, -2:], dt_all[-2:])
        return StrapdownStep(c_end, product(c_start, r_mean), np.einsum("ijn,jn->in", c_start, dv_body))
