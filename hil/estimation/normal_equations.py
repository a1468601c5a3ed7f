"""Least squares in information form: sums of H^T H, H^T z and z^T z, added batch by batch.

The small symmetric systems are solved with ``numpy.linalg``, which numpy has loaded already:
``scipy.linalg`` would add 0.2 s to the start-up of every trial.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np


def unit_diagonal(info: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A symmetric matrix (or a stack of them) scaled to unit diagonal, ``D info D``, and the scale factors ``diag(D)``."""
    diag = np.diagonal(info, axis1=-2, axis2=-1)
    scale = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    return info * (scale[..., :, None] * scale[..., None, :]), scale


def require_finite(a: np.ndarray) -> None:
    """Raise ValueError if ``a`` holds an inf or NaN."""
    if not np.isfinite(a).all():
        raise ValueError("array must not contain infs or NaNs")


def symmetric_eigenvalues(a: np.ndarray, check_finite: bool = True) -> np.ndarray:
    """Eigenvalues of a symmetric matrix (or a stack of them; lower triangle), ascending."""
    if check_finite:
        require_finite(a)
    return np.linalg.eigvalsh(a)


class NormalEquations:
    """Accumulates the normal equations of ``z = [H G] x + noise``; the sums equal those of one batch solve.

    ``H`` (n columns) is always given; ``G`` (``border`` further columns) is optional per call and fills
    the border of the sums. The two parts are summed separately so that the leading n x n block is the
    same, to the last bit, whether a border is kept or not.
    """

    def __init__(self, n: int, border: int = 0) -> None:
        self.n = n
        self.info = np.zeros((n + border, n + border))
        self.rhs = np.zeros(n + border)
        self.zz = 0.0
        self.samples = 0

    def add(self, h: np.ndarray, z: np.ndarray, g: np.ndarray | None = None) -> None:
        """Add N measurements: H (N, m, n), z (N, m) and optionally G (N, m, border)."""
        for _ in self.add_segments(h, z, [len(z)], g=g):
            pass

    def add_segments(self, h: np.ndarray, z: np.ndarray, stops: Sequence[int],
                     accept: np.ndarray | None = None, g: np.ndarray | None = None) -> Iterator[int]:
        """Add the measurements up to each index in ``stops`` (increasing, the last = N), yielding after each;
        ``accept`` (N,) bool leaves out the measurements marked False; ``g`` (N, m, border) the border columns."""
        if accept is not None and not accept.all():
            h, z = h * accept[:, None, None], z * accept[:, None]
            g = None if g is None else g * accept[:, None, None]
        n = self.n
        start = 0
        for stop in stops:
            if stop > start:
                hs, zs = h[start:stop], z[start:stop]
                rows, values = hs.reshape(-1, n), zs.reshape(-1)  # the stacked rows: one BLAS product each
                self.info[:n, :n] += rows.T @ rows
                self.rhs[:n] += rows.T @ values
                self.zz += float(values @ values)
                if g is not None:
                    self._add_border(rows, values, g[start:stop])
                self.samples += stop - start if accept is None else int(accept[start:stop].sum())
            start = stop
            yield stop

    def _add_border(self, rows_h: np.ndarray, values: np.ndarray, gs: np.ndarray) -> None:
        """The border sums ``H^T G``, ``G^T G``, ``G^T z`` as matrix products of the stacked rows."""
        n = self.n
        rows_g = gs.reshape(-1, gs.shape[-1])
        cross = rows_h.T @ rows_g
        self.info[:n, n:] += cross
        self.info[n:, :n] += cross.T
        self.info[n:, n:] += rows_g.T @ rows_g
        self.rhs[n:] += rows_g.T @ values

    def scaled(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The leading n x n block scaled to unit diagonal, and the scale factors."""
        return unit_diagonal(self.info[:n, :n])
