"""Turntable attitudes for many samples at once, in closed form and component-major.

``C_b^n = C_table^n Rz(outer) Rx(middle) Ry(inner) C_b^mount`` as :meth:`hil.frames.TableGeometry.attitude_matrix`
defines it, but with the gimbal product written out element by element on arrays laid out (3, 3, N):
a stacked (N, 3, 3) matrix product costs 0.2-0.5 us per matrix in per-matrix BLAS calls, the written-out
product ~0.05 us. The constant table and mounting rotations are applied as one matrix product over all
samples, and skipped when they are the identity. The results agree with ``attitude_matrix`` to rounding
(the BLAS kernels fuse multiply and add).
"""

from __future__ import annotations

import numpy as np

from hil.frames import TableGeometry


def gimbal_matrices(geometry: TableGeometry, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(C_b^n, Rx(middle) Ry(inner)), each (3, 3, N), from gimbal angles (N, 3) ordered (outer, middle, inner).

    Row 0 of the second is also Ry(inner)'s row 0, and its row 2 is ``Ry^T Rx^T z``: what the body rate needs.
    """
    angles = np.atleast_2d(angles)
    cos, sin = np.cos(angles.T), np.sin(angles.T)
    cz, cx, cy = cos
    sz, sx, sy = sin
    middle_inner = np.empty((3, 3, len(angles)))  # filled row by row: no temporaries to stack
    middle_inner[0, 0], middle_inner[0, 1], middle_inner[0, 2] = cy, 0.0, sy
    np.multiply(sx, sy, out=middle_inner[1, 0])
    middle_inner[1, 1] = cx
    np.negative(sx, out=middle_inner[1, 2])
    middle_inner[1, 2] *= cy
    np.negative(cx, out=middle_inner[2, 0])
    middle_inner[2, 0] *= sy
    middle_inner[2, 1] = sx
    np.multiply(cx, cy, out=middle_inner[2, 2])
    p0, p1 = middle_inner[0], middle_inner[1]
    c = np.empty_like(middle_inner)
    np.multiply(cz, p0, out=c[0])
    c[0] -= sz * p1
    np.multiply(sz, p0, out=c[1])
    c[1] += cz * p1
    c[2] = middle_inner[2]
    table, mount = geometry.table_to_n_matrix, geometry.body_to_mount_matrix
    if not np.array_equal(table, np.eye(3)):
        c = (table @ c.reshape(3, -1)).reshape(c.shape)
    if not np.array_equal(mount, np.eye(3)):
        c = np.einsum("ikn,kj->ijn", c, mount)
    return c, middle_inner


def row_times(v: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``v^T C`` for a constant 3-vector v and matrices C (3, 3, N), (3, N)."""
    return v[0] * c[0] + v[1] * c[1] + v[2] * c[2]


def as_stacked(c: np.ndarray) -> np.ndarray:
    """(3, 3, N) component-major matrices as a contiguous (N, 3, 3) stack."""
    return np.ascontiguousarray(c.transpose(2, 0, 1))
