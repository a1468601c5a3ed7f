"""When an estimate has converged: a definition that does not depend on how long the trial went on.

An estimate ``x(t_j)`` (one per solve, per axis) with its 1-sigma ``s(t_j)`` is *settled* when it is
known to the tolerance, ``3 s(t_j) <= tolerance``, and every later estimate lies within ``tolerance``
of it. The convergence time is the first solve instant from which on every estimate is settled; None
if the last one is not (the trial ended before the estimate converged).

Neither condition involves the final sigma, which shrinks with the trial's length: a longer trial only
adds later estimates, each within ~``s(t_j)`` of the settled ``x(t_j)``, so it moves the convergence
time only by a 3-sigma excursion. An absolute tolerance (rather than the running 3 sigma alone) is
needed because the first estimates, with their large sigma, are trivially consistent with everything
after them.
"""

from __future__ import annotations

import numpy as np

from hil.units import UG

SECONDS_PER_DAY = 86400.0
# The 2019 paper's criterion (Fig. 6: the bias within 10 ug, "convergent after about 500 s"); the drift
# tolerance is the rate that moves the bias by the same amount over a day (0.42 ug/h).
BIAS_TOLERANCE = 10.0 * UG  # m/s^2
DRIFT_TOLERANCE = BIAS_TOLERANCE / SECONDS_PER_DAY  # m/s^3


def convergence_time(t: np.ndarray, estimates: np.ndarray, sigmas: np.ndarray, tolerance: float) -> float | None:
    """First solve instant from which every estimate is settled (see the module docstring).

    ``t`` (K,) increasing, ``estimates`` and ``sigmas`` (K, m), NaN where no estimate was formed (not
    settled); ``tolerance`` in the estimates' unit.
    """
    t, estimates, sigmas = np.asarray(t, float), np.asarray(estimates, float), np.asarray(sigmas, float)
    if not len(t):
        return None
    later_max = np.fmax.accumulate(estimates[::-1], axis=0)[::-1]  # max over j..K-1
    later_min = np.fmin.accumulate(estimates[::-1], axis=0)[::-1]
    spread = np.zeros_like(estimates)  # farthest later estimate, per axis
    spread[:-1] = np.maximum(later_max[1:] - estimates[:-1], estimates[:-1] - later_min[1:])
    settled = np.all((3.0 * sigmas <= tolerance) & (spread <= tolerance), axis=1)  # NaN compares False
    if not settled[-1]:
        return None
    unsettled = np.flatnonzero(~settled)
    return float(t[unsettled[-1] + 1]) if len(unsettled) else float(t[0])


class SolveTrack:
    """One row per solve, kept in full (the snapshot history is thinned): ``[t, x(m), sigma(m)]`` per quantity."""

    def __init__(self, width: int) -> None:
        self._rows = np.empty((256, width))
        self._n = 0

    def append(self, row: np.ndarray) -> None:
        if self._n == len(self._rows):
            self._rows = np.vstack((self._rows, np.empty_like(self._rows)))
        self._rows[self._n] = row
        self._n += 1

    @property
    def rows(self) -> np.ndarray:
        return self._rows[: self._n]
