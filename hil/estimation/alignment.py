"""Dual-vector alignment with reconstructed apparent-gravity vectors (Liu et al. 2014).

The two vectors are the apparent gravity reconstructed from the current parameters at 0 and at t
(2014 eq. 17) in i_b0, and the theoretical specific force at rest in n0 at the same instants
(2014 eq. 7). ``C_ib0^n0`` follows from the dual-vector construction (2014 eq. 8), orthogonalised
(eq. 9), and the body attitude is ``C_b^n(t) = C_n0^n(t) C_ib0^n0 C_b^ib0(t)`` (eq. 1).
Method 1 reconstructs from the 9-state parameters, method 2 from the 12-state ones, whose
gravity part is free of the accelerometer bias (2019 Sec. IV).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.estimation.strapdown import rotation_matrices
from hil.frames import Earth, euler_from_matrix


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """u x v of two 3-vectors, as ``np.cross`` forms it (without its axis handling)."""
    return np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]])


def dual_vector(v1_b: np.ndarray, v2_b: np.ndarray, v1_n: np.ndarray, v2_n: np.ndarray) -> np.ndarray:
    """C such that v_n = C v_b, from two non-collinear vector pairs (2014 eqs. 8-9), orthogonalised."""

    def triad(v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
        c = _cross(v1, v2)
        return np.vstack((v1, c, _cross(c, v1)))

    c = np.linalg.solve(triad(v1_b, v2_b), triad(v1_n, v2_n)).T
    u, _, vt = np.linalg.svd(c)
    return u @ vt  # the orthogonal polar factor, C (C^T C)^(-1/2)


@dataclass(frozen=True)
class EarthTurn:
    """What the alignment at time t needs of the earth's rotation since the start (formed once per solve)."""

    f_n0_t: np.ndarray  # (3,) the specific force at rest at t, in n0
    c_n0_n: np.ndarray  # (3, 3) C_n0^n(t)

    @classmethod
    def at(cls, t: float, earth: Earth) -> EarthTurn:
        c_n_n0 = rotation_matrices((t * earth.omega_n)[None])[0]  # earth.n_to_n0(t), without scipy's input handling
        return cls(c_n_n0 @ earth.f_n, c_n_n0.T)


def alignment_matrix(apparent_gravity_0: np.ndarray, apparent_gravity_t: np.ndarray, turn: EarthTurn,
                     earth: Earth) -> np.ndarray:
    """C_ib0^n0 from the reconstructed apparent gravity at 0 and t (each (3,))."""
    return dual_vector(apparent_gravity_0, apparent_gravity_t, earth.f_n, turn.f_n0_t)


def body_attitude(c_ib0_n0: np.ndarray, c_b_ib0: np.ndarray, turn: EarthTurn) -> np.ndarray:
    """C_b^n(t) = C_n0^n(t) C_ib0^n0 C_b^ib0(t)."""
    return turn.c_n0_n @ c_ib0_n0 @ c_b_ib0


def attitude_error(estimate: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(pitch, roll, yaw) of the estimate minus the reference, rad, wrapped to (-pi, pi]."""
    diff = euler_from_matrix(estimate) - euler_from_matrix(reference)
    diff = (diff + np.pi) % (2 * np.pi) - np.pi
    return np.array([diff[1], diff[2], diff[0]])


def theoretical_error(bias_b: np.ndarray, c_b_n: np.ndarray, g: float) -> np.ndarray:
    """(pitch, roll) error set by an accelerometer bias (2019 eq. 8): phi_E = b_N/g, phi_N = -b_E/g.

    The misalignment acts as ``C_b^n' = exp(phi x) C_b^n``; the result is the Euler difference it makes.
    """
    b_n = c_b_n @ bias_b
    phi = np.array([b_n[1] / g, -b_n[0] / g, 0.0])
    tilted = rotation_matrices(phi[None])[0] @ c_b_n
    return attitude_error(tilted, c_b_n)[:2]
