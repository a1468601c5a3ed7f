"""Dual-vector alignment with reconstructed apparent-gravity vectors (Liu et al. 2014).

The two vectors are the apparent gravity reconstructed from the current parameters at 0 and at t
(2014 eq. 17) in i_b0, and the theoretical specific force at rest in n0 at the same instants
(2014 eq. 7). ``C_ib0^n0`` follows from the dual-vector construction (2014 eq. 8), orthogonalised
(eq. 9), and the body attitude is ``C_b^n(t) = C_n0^n(t) C_ib0^n0 C_b^ib0(t)`` (eq. 1).
Method 1 reconstructs from the 9-state parameters, method 2 from the 12-state ones, whose
gravity part is free of the accelerometer bias (2019 Sec. IV).

Every function takes a stack of instants (leading axes) as well as one: a batch's snapshots are aligned
at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.estimation.apparent_gravity import reconstruction_basis
from hil.estimation.strapdown import cross
from hil.frames import Earth, euler_from_matrix, level_angles, wrapped


def _unit(v: np.ndarray) -> np.ndarray:
    """v scaled to unit length along the last axis; NaN for a zero vector (parallel vectors have no triad: the
    first solution after a gap at the trial's start, one sample in)."""
    v = np.ascontiguousarray(v)  # einsum's sum along a strided axis rounds differently
    with np.errstate(invalid="ignore"):
        return v / np.sqrt(np.einsum("...i,...i->...", v, v))[..., None]


def unit_triad(v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """The rows ``v1, v1 x v2, (v1 x v2) x v1`` of a 2014 eq. 8 triad, each scaled to unit length, from
    vectors (3,) or (K, 3): (3, 3) or (K, 3, 3)."""
    c = cross(v1.T, v2.T).T  # the strapdown's cross product, along the first axis
    return np.stack((_unit(np.broadcast_to(v1, c.shape)), _unit(c), _unit(cross(c.T, v1.T).T)), axis=-2)


@dataclass(frozen=True)
class EarthTurn:
    """What the alignment at times t needs of the earth's rotation since the start (formed once per solve);
    each field has the leading shape of t."""

    f_n0_t: np.ndarray  # (..., 3) the specific force at rest at t, in n0
    c_n0_n: np.ndarray  # (..., 3, 3) C_n0^n(t)
    triad_n0: np.ndarray  # (..., 3, 3) unit_triad(f^n, f^n0(t)): the n0 side of eq. 8, common to both methods
    basis: np.ndarray  # (..., 2, 3) reconstruction_basis at 0 and t (2014 eq. 17)

    @classmethod
    def at(cls, t: float | np.ndarray, earth: Earth) -> EarthTurn:
        """The turn t s after the start (a float or (K,) times): C_n^n0(t) from :meth:`Earth.turn_matrices`
        (2014 eq. 3)."""
        shape = np.shape(t)
        times = np.atleast_1d(np.asarray(t, dtype=float))
        c_n_n0 = earth.turn_matrices(times)
        f_n0_t = c_n_n0 @ earth.f_n
        basis = np.stack((np.broadcast_to(reconstruction_basis(0.0)[0], (len(times), 3)), reconstruction_basis(times)),
                         axis=1)
        turn = (f_n0_t, c_n_n0.transpose(0, 2, 1), unit_triad(earth.f_n, f_n0_t), basis)
        return cls(*(a.reshape(shape + a.shape[1:]) for a in turn))

    def apparent_gravity(self, a_internal: np.ndarray) -> np.ndarray:
        """The reconstructed apparent gravity at 0 and t, (..., 2, 3), from the 9 parameters (..., 3, 3) of a
        solution (``Solution.apparent_gravity([0, t])``), with the basis formed once for both methods."""
        return self.basis @ np.swapaxes(a_internal, -1, -2)


def alignment_matrix(apparent_gravity_0: np.ndarray, apparent_gravity_t: np.ndarray, turn: EarthTurn) -> np.ndarray:
    """C_ib0^n0 such that v_n0 = C v_ib0, from the reconstructed apparent gravity at 0 and t (each (..., 3)) and the
    specific force at rest in n0 at the same instants, whose triad ``turn`` holds (2014 eq. 8), orthogonalised
    (eq. 9).

    The rows of each eq.-8 triad are mutually orthogonal, so eq. 8 is ``C = N^T D B`` with N and B the
    triads scaled to unit rows (orthogonal matrices) and D = diag(|n_i| / |b_i|) positive. Its
    orthogonal polar factor ``C (C^T C)^(-1/2)`` (eq. 9) is therefore ``N^T B``, formed here directly.
    """
    return np.swapaxes(turn.triad_n0, -1, -2) @ unit_triad(apparent_gravity_0, apparent_gravity_t)


def body_attitude(c_ib0_n0: np.ndarray, c_b_ib0: np.ndarray, turn: EarthTurn) -> np.ndarray:
    """C_b^n(t) = C_n0^n(t) C_ib0^n0 C_b^ib0(t)."""
    return turn.c_n0_n @ c_ib0_n0 @ c_b_ib0


def attitude_error(estimate: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(pitch, roll, yaw) of the estimate minus the reference, rad, wrapped to [-pi, pi); (..., 3)."""
    return wrapped(euler_from_matrix(estimate) - euler_from_matrix(reference))[..., [1, 2, 0]]


def theoretical_error(bias_b: np.ndarray, c_b_n: np.ndarray, g: float) -> np.ndarray:
    """(pitch, roll) error set by an accelerometer bias (2019 eq. 8): phi_E = b_N/g, phi_N = -b_E/g; (..., 2).

    The misalignment acts as ``C_b^n' = exp(phi x) C_b^n``; the result is the Euler difference it makes.
    Pitch and roll depend on the last row of C_b^n only, which for the level phi (Rodrigues) becomes
    ``cos|phi| C[2] + sin|phi|/|phi| (phi_E C[1] - phi_N C[0])``.
    """
    east, north, up = c_b_n[..., 0, :], c_b_n[..., 1, :], c_b_n[..., 2, :]
    phi_e = np.einsum("...i,...i->...", north, bias_b)[..., None] / g
    phi_n = -np.einsum("...i,...i->...", east, bias_b)[..., None] / g
    angle = np.hypot(phi_e, phi_n)
    sinc = np.sinc(angle / np.pi)  # sin(angle) / angle, 1 at 0
    tilted = np.cos(angle) * up + sinc * (phi_e * north - phi_n * east)
    return wrapped(level_angles(tilted) - level_angles(up))
