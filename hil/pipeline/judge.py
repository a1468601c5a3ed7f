"""The judge stage: the checks between the wire checksum and the estimator. Each IMU read's samples are marked
where the device flags them invalid (:class:`~hil.pipeline.health.HealthCheck`: they are never estimated) and the
others held to physical plausibility (:class:`~hil.pipeline.plausibility.ImuPlausibility`) before they are paired; each
block the estimator is about to take, to the rotation the table angles show (:class:`~hil.pipeline.plausibility.
GyroTableGate`): its rejected samples, and those the device flagged, become gaps the estimator bridges. A run of
rejections as long as ``STALL_S`` stalls the trial, with the diagnosis of the check that rejected last."""

from __future__ import annotations

import numpy as np

from drivers.codec import HealthFlag
from hil.frames import Earth, TableGeometry
from hil.pipeline.health import HealthCheck
from hil.pipeline.plausibility import RATE_MARGIN, GyroTableGate, ImuPlausibility, RejectionWatch, UnitKeys
from hil.pipeline.blocks import part
from hil.samples import AlignedBatch, ImuGap, ImuSamples
from hil.units import DEG


class Judge:
    """The health flags (``flags``, the IMU codec's), the plausibility check and the gyro/table gate of a trial at
    ``rate_hz`` on a table whose fastest gimbal rate limit is ``max_rate_dps``; without ``table_gate`` the gyro is
    not held to the table's rotation (``estimator.gyro_table_gate``); without ``flags_stall`` samples the device
    flags do not end a trial however long they last (``estimator.flags_end_trial``)."""

    def __init__(self, earth: Earth, geometry: TableGeometry, rate_hz: float, max_rate_dps: float,
                 flags: tuple[HealthFlag, ...] = (), table_gate: bool = True, flags_stall: bool = True) -> None:
        self.rate_hz = rate_hz
        self.table_gate = table_gate
        self.flags_stall = flags_stall
        self.health = HealthCheck(flags)
        self.plausibility = ImuPlausibility(rate_hz, earth.g, RATE_MARGIN * max_rate_dps * DEG)
        self.gate = GyroTableGate(earth, geometry)
        self.watch = RejectionWatch(rate_hz)
        self._stalled_by: ImuPlausibility | GyroTableGate | HealthCheck | None = None
        self._previous: tuple[float, np.ndarray] | None = None  # (t, angles) of the last sample gated

    def plausible(self, samples: ImuSamples) -> ImuSamples:
        """One read's samples but the implausible, those the device flags invalid marked so (not judged for
        plausibility: a flagged sample's values may be anything)."""
        samples = self.health.marked(samples)
        valid = samples.valid
        good = np.ones(len(samples), dtype=bool)
        good[valid] = self.plausibility.ok(samples.dtheta[valid], samples.dv[valid])
        if good.all():
            return samples
        self._rejected(self.plausibility, len(good) - int(good.sum()))
        return samples.take(good)

    def gated(self, run: AlignedBatch) -> list[AlignedBatch | ImuGap]:
        """A block split where the device flagged a sample invalid or the gyro disagrees with the table: those
        samples become bridged gaps (a run of flagged samples one gap). The gate does not judge a block with a
        sample without angles, or after one."""
        previous = self._previous
        self._previous = (float(run.t[-1]), run.angles[-1])
        valid = np.ones(len(run), dtype=bool) if run.valid is None else run.valid
        t_end, angles = run.t, run.angles
        first = previous if previous is not None else (float(t_end[0]) - 1.0 / self.rate_hz, angles[0])
        t_start = np.concatenate(([first[0]], t_end[:-1]))
        starts = np.vstack((first[1], angles[:-1]))
        good = valid.copy()
        if self.table_gate and not (previous is None or np.isnan(previous[1]).any() or np.isnan(angles).any()):
            good[valid] = self.gate.consistent(t_start[valid], t_end[valid], starts[valid], angles[valid],
                                               run.dtheta[valid])
        if good.any():
            self.watch.taken(len(good) - 1 - int(np.flatnonzero(good)[-1]))
        elif valid.any() or self.flags_stall:
            self._rejected(self.gate if valid.any() else self.health, len(good))
        if good.all():
            return [run]
        out: list[AlignedBatch | ImuGap] = []
        k = 0
        while k < len(good):
            stop = k + 1
            if good[k] or not valid[k]:  # a run of good samples, or of flagged ones
                same = good[k:] if good[k] else ~valid[k:]
                stop = k + int(np.argmin(same)) if not same.all() else len(good)
            if good[k]:
                out.append(part(run, k, stop))
            else:
                out.append(ImuGap(t_start[k], t_end[stop - 1], tuple(starts[k].tolist()),
                                  tuple(angles[stop - 1].tolist())))
            k = stop
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

    def counts(self) -> dict[str, int | dict[str, int]]:
        """The samples each check rejected, and those the device flagged (in all and by flag)."""
        return {"imu_implausible": self.plausibility.rejected, "imu_gated": self.gate.rejected,
                **self.health.counts()}

    def _rejected(self, by: ImuPlausibility | GyroTableGate | HealthCheck, n: int) -> None:
        self.watch.rejected(n)
        self._stalled_by = by
