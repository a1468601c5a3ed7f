"""Dual-vector alignment with reconstructed apparent-gravity vectors (Liu et al. 2014).

The two vectors are the apparent gravity reconstructed from the current parameters at 0 and at t
(2014 eq. 17) in i_b0, and the theoretical specific force at rest in n0 at the same instants
(2014 eq. 7). ``C_ib0^n0`` follows from the dual-vector construction (2014 eq. 8), orthogonalised
(eq. 9), and the body attitude is ``C_b^n(t) = C_n0^n(t) C_ib0^n0 C_b^ib0(t)`` (eq. 1).
Method 1 reconstructs from the 9-state parameters, method 2 from the 12-state ones, whose
gravity part is free of the accelerometer bias (2019 Sec. IV).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hil.estimation.apparent_gravity import Solution, reconstruction_basis
from hil.frames import Earth, euler_from_matrix, level_angles


def _cross(u: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    """u x v of two 3-vectors."""
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def _unit(v: Sequence[float]) -> list[float]:
    """v scaled to unit length."""
    norm = math.hypot(*v)
    return [x / norm for x in v]


def unit_triad(v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """The rows ``v1, v1 x v2, (v1 x v2) x v1`` of a 2014 eq. 8 triad, each scaled to unit length (3, 3)."""
    a = v1.tolist()
    c = _cross(a, v2.tolist())
    return np.array([_unit(a), _unit(c), _unit(_cross(c, a))])


@dataclass(frozen=True)
class EarthTurn:
    """What the alignment at time t needs of the earth's rotation since the start (formed once per solve)."""

    f_n0_t: np.ndarray  # (3,) the specific force at rest at t, in n0
    c_n0_n: np.ndarray  # (3, 3) C_n0^n(t)
    triad_n0: np.ndarray  # (3, 3) unit_triad(f^n, f^n0(t)): the n0 side of eq. 8, common to both methods
    basis: np.ndarray  # (2, 3) reconstruction_basis at 0 and t (2014 eq. 17)

    @classmethod
    def at(cls, t: float, earth: Earth) -> EarthTurn:
        """The turn t s after the start: C_n^n0(t) from :meth:`Earth.turn_matrices` (2014 eq. 3)."""
        c_n_n0 = earth.turn_matrices(t)[0]
        f_n = earth.f_n
        f_n0_t = c_n_n0 @ f_n
        return cls(f_n0_t, c_n_n0.T, unit_triad(f_n, f_n0_t), reconstruction_basis(np.array([0.0, t])))

    def apparent_gravity(self, solution: Solution) -> np.ndarray:
        """``solution.apparent_gravity([0, t])``, (2, 3), with the basis formed once for both methods."""
        return self.basis @ solution.a_internal.T


def alignment_matrix(apparent_gravity_0: np.ndarray, apparent_gravity_t: np.ndarray, turn: EarthTurn) -> np.ndarray:
    """C_ib0^n0 such that v_n0 = C v_ib0, from the reconstructed apparent gravity at 0 and t (each (3,)) and the
    specific force at rest in n0 at the same instants, whose triad ``turn`` holds (2014 eq. 8), orthogonalised
    (eq. 9).

    The rows of each eq.-8 triad are mutually orthogonal, so eq. 8 is ``C = N^T D B`` with N and B the
    triads scaled to unit rows (orthogonal matrices) and D = diag(|n_i| / |b_i|) positive. Its
    orthogonal polar factor ``C (C^T C)^(-1/2)`` (eq. 9) is therefore ``N^T B``, formed here directly.
    """
    return turn.triad_n0.T @ unit_triad(apparent_gravity_0, apparent_gravity_t)


def body_attitude(c_ib0_n0: np.ndarray, c_b_ib0: np.ndarray, turn: EarthTurn) -> np.ndarray:
    """C_b^n(t) = C_n0^n(t) C_ib0^n0 C_b^ib0(t)."""
    return turn.c_n0_n @ c_ib0_n0 @ c_b_ib0


def _differences(angles: Sequence[float], reference: Sequence[float]) -> list[float]:
    """``angles - reference`` (rad), each wrapped to [-pi, pi)."""
    return [(a - b + math.pi) % (2 * math.pi) - math.pi for a, b in zip(angles, reference)]


def attitude_error(estimate: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(pitch, roll, yaw) of the estimate minus the reference, rad, wrapped to [-pi, pi)."""
    yaw, pitch, roll = _differences(euler_from_matrix(estimate), euler_from_matrix(reference))
    return np.array([pitch, roll, yaw])


def theoretical_error(bias_b: np.ndarray, c_b_n: np.ndarray, g: float) -> np.ndarray:
    """(pitch, roll) error set by an accelerometer bias (2019 eq. 8): phi_E = b_N/g, phi_N = -b_E/g.

    The misalignment acts as ``C_b^n' = exp(phi x) C_b^n``; the result is the Euler difference it makes.
    Pitch and roll depend on the last row of C_b^n only, which for the level phi (Rodrigues) becomes
    ``cos|phi| C[2] + sin|phi|/|phi| (phi_E C[1] - phi_N C[0])``.
    """
    east, north, up = c_b_n.tolist()
    b_east, b_north = (c_b_n[:2] @ bias_b).tolist()
    phi_e, phi_n = b_north / g, -b_east / g
    angle = math.hypot(phi_e, phi_n)
    cos, sinc = math.cos(angle), (math.sin(angle) / angle if angle else 1.0)
    tilted = [cos * u + sinc * (phi_e * n - phi_n * e) for e, n, u in zip(east, north, up)]
    return np.array(_differences(level_angles(tilted), level_angles(up)))
