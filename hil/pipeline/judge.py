"""The judge stage: the checks between the wire checksum and the estimator. Each IMU read's samples are held
to physical plausibility (:class:`~hil.pipeline.plausibility.ImuPlausibility`) before they are paired; each
block the estimator is about to take, to the rotation the table angles show (:class:`~hil.pipeline.plausibility.
GyroTableGate`): its rejected samples become gaps the estimator bridges. A run of rejections as long as
``STALL_S`` stalls the trial, with the diagnosis of the check that rejected last."""

from __future__ import annotations

import numpy as np

from hil.frames import Earth, TableGeometry
from hil.pipeline.plausibility import RATE_MARGIN, GyroTableGate, ImuPlausibility, RejectionWatch, UnitKeys
from hil.pipeline.blocks import part
from hil.samples import AlignedBatch, ImuGap, ImuSamples
from hil.units import DEG


class Judge:
    """The plausibility check and the gyro/table gate of a trial at ``rate_hz`` on a table whose fastest gimbal
    rate limit is ``max_rate_dps``."""

    def __init__(self, earth: Earth, geometry: TableGeometry, rate_hz: float, max_rate_dps: float) -> None:
        self.rate_hz = rate_hz
        self.plausibility = ImuPlausibility(rate_hz, earth.g, RATE_MARGIN * max_rate_dps * DEG)
        self.gate = GyroTableGate(earth, geometry)
        self.watch = RejectionWatch(rate_hz)
        self._stalled_by: ImuPlausibility | GyroTableGate | None = None
        self._previous: tuple[float, np.ndarray] | None = None  # (t, angles) of the last sample gated

    def plausible(self, samples: ImuSamples) -> ImuSamples:
        """One read's plausible samples."""
        good = self.plausibility.ok(samples.dtheta, samples.dv)
        if good.all():
            return samples
        self._rejected(self.plausibility, len(good) - int(good.sum()))
        return samples.take(good)

    def gated(self, run: AlignedBatch) -> list[AlignedBatch | ImuGap]:
        """A block split where the gyro disagrees with the table: those samples become bridged gaps. A block
        with a sample without angles, or after one, is taken whole."""
        previous = self._previous
        self._previous = (float(run.t[-1]), run.angles[-1])
        if previous is None or np.isnan(previous[1]).any() or np.isnan(run.angles).any():
            self.watch.taken()
            return [run]
        t_end, angles = run.t, run.angles
        t_start = np.concatenate(([previous[0]], t_end[:-1]))
        starts = np.vstack((previous[1], angles[:-1]))
        good = self.gate.consistent(t_start, t_end, starts, angles, run.dtheta)
        if good.any():
            self.watch.taken(len(good) - 1 - int(np.flatnonzero(good)[-1]))
        else:
            self._rejected(self.gate, len(good))
        if good.all():
            return [run]
        out: list[AlignedBatch | ImuGap] = []
        k = 0
        while k < len(good):
            if good[k]:
                stop = k + int(np.argmin(good[k:])) if not good[k:].all() else len(good)
                out.append(part(run, k, stop))
                k = stop
            else:
                out.append(ImuGap(t_start[k], t_end[k], tuple(starts[k]), tuple(angles[k].tolist())))
                k += 1
        return out

    def after_gap(self, gap: ImuGap) -> None:
        """The aligner bridged lost samples: the next block is gated from the angles at the gap's end."""
        self._previous = (gap.t_end, np.asarray(gap.angles_end, dtype=float))

    def stalled(self, keys: UnitKeys) -> str | None:
        """Why every IMU sample has been rejected for the last ``STALL_S`` (naming the likely config key among
        ``keys``), or None while samples reach the estimator."""
        if not self.watch.stalled or self._stalled_by is None:
            return None
        return (f"every IMU sample for {self.watch.run / self.rate_hz:.1f} s was rejected: "
                f"{self._stalled_by.diagnosis(keys)}")

    def counts(self) -> dict[str, int]:
        """The samples each check rejected."""
        return {"imu_implausible": self.plausibility.rejected, "imu_gated": self.gate.rejected}

    def _rejected(self, by: ImuPlausibility | GyroTableGate, n: int) -> None:
        self.watch.rejected(n)
        self._stalled_by = by
