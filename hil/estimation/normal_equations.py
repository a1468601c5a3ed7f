"""Least squares in information form: sums of H^T H, H^T z and z^T z, added batch by batch."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np


class NormalEquations:
    """Accumulates the normal equations of ``z = H x + noise``; the sums equal those of one batch solve."""

    def __init__(self, n: int) -> None:
        self.info = np.zeros((n, n))
        self.rhs = np.zeros(n)
        self.zz = 0.0
        self.samples = 0

    def add(self, h: np.ndarray, z: np.ndarray) -> None:
        """Add N measurements: H (N, m, n) and z (N, m)."""
        for _ in self.add_segments(h, z, [len(z)]):
            pass

    def add_segments(self, h: np.ndarray, z: np.ndarray, stops: Sequence[int],
                     accept: np.ndarray | None = None) -> Iterator[int]:
        """Add the measurements up to each index in ``stops`` (increasing, the last = N), yielding after each;
        ``accept`` (N,) bool leaves out the measurements marked False."""
        if accept is not None and not accept.all():
            h, z = h * accept[:, None, None], z * accept[:, None]
        start = 0
        for stop in stops:
            if stop > start:
                hs, zs = h[start:stop], z[start:stop]
                self.info += np.einsum("nri,nrj->ij", hs, hs)
                self.rhs += np.einsum("nri,nr->i", hs, zs)
                self.zz += float(np.einsum("ni,ni->", zs, zs))
                self.samples += stop - start if accept is None else int(accept[start:stop].sum())
            start = stop
            yield stop

    def scaled(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The leading n x n block scaled to unit diagonal, and the scale factors."""
        diag = np.diag(self.info)[:n]
        scale = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
        return self.info[:n, :n] * np.outer(scale, scale), scale
