"""The estimate stage: blocks, gaps and batches into the :class:`~hil.estimation.online.OnlineEstimator`
(started at the first sample's interval), and the gyro/table data into the time-offset check
(:mod:`hil.pipeline.time_offset`); what it took comes out as :class:`~hil.pipeline.progress.Taken`."""

from __future__ import annotations

import numpy as np

from hil.estimation.online import OnlineEstimator
from hil.pipeline.progress import Taken
from hil.pipeline.settings import PipelineSettings
from hil.pipeline.time_offset import TimeOffsetEstimator
from hil.samples import AlignedBatch, ImuGap


class Estimation:
    """The estimator of a trial (None until its first sample) and its time-offset check; ``updates`` counts
    the blocks taken, ``bridged_without_table`` the aligner's gaps bridged without the table's angles."""

    def __init__(self, settings: PipelineSettings) -> None:
        self.settings = settings.estimator
        self.earth = settings.earth
        self.geometry = settings.geometry
        self.estimator: OnlineEstimator | None = None
        self.time_offset = TimeOffsetEstimator(settings.earth, settings.geometry, settings.imu_rate_hz)
        self.updates = 0
        self.bridged_without_table = 0

    def start(self, t0: float) -> None:
        """The estimator, its ``i_b0`` instant at ``t0`` (s)."""
        s = self.settings
        self.estimator = OnlineEstimator(self.earth, self.geometry, 1.0 / s.solve_rate_hz, s.rank_tolerance, t0=t0,
                                         bias_model=s.bias_model)

    def block(self, block: AlignedBatch, gated: list[AlignedBatch | ImuGap]) -> Taken:
        """One block, as the judge split it (the samples it rejected as gaps, bridged)."""
        self.updates += 1
        t0 = self.estimator.t0
        samples = []
        for run in gated:
            if isinstance(run, ImuGap):
                self.estimator.bridge(run)
                self.time_offset.restart()
                continue
            self.estimator.update_many(run)
            self.time_offset.add(run.t, run.dtheta, run.angles)
            samples.append(AlignedBatch(run.t - t0, run.dtheta, run.dv, run.angles))
        with_angles = ~np.isnan(block.angles[:, 0])
        return Taken(tuple(samples), block.t[with_angles] - t0, block.angles[with_angles])

    def gap(self, gap: ImuGap) -> None:
        """IMU samples the aligner could not fill: bridged with the table's angles when it has them."""
        self.bridged_without_table += not self.estimator.bridge(gap)
        self.time_offset.restart()

    def batch(self, batch: AlignedBatch) -> Taken:
        """Samples that needed no alignment (a simulation's, a CSV's), whole."""
        self.estimator.update_many(batch)
        t = batch.t - self.estimator.t0
        angles = batch.angle_rows()
        with_angles = ~np.isnan(angles[:, 0])
        samples = (AlignedBatch(t, batch.dtheta, batch.dv, angles),) if len(batch) else ()
        return Taken(samples, t[with_angles], angles[with_angles])

    def time_offset_s(self) -> float | None:
        """The table's lag behind the IMU (s) over the data so far; None before it can be measured."""
        return self.time_offset.estimate() if self.estimator is not None else None

    def gyro_rate_error(self) -> np.ndarray | None:
        """The gyros' rate minus the table's per body axis (3,) rad/s over the data so far; None before it can
        be measured."""
        return self.time_offset.gyro_rate_error() if self.estimator is not None else None
