"""What one IMU's pipeline takes from a trial's config, read once by :meth:`PipelineSettings.of`: the stages
receive these settings (and the config blocks they name), never the whole config, and no module of the
pipeline imports :mod:`hil.config` (docs/architecture.md, "The stages and the hops of a live read")."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drivers.codec import Codec
from drivers.controllers import data_codec
from drivers.registry import imu_codec
from hil.frames import Earth, TableGeometry
from hil.vocabulary import Stream


@dataclass(frozen=True)
class PipelineSettings:
    """The site, the table's geometry and limits, the IMU's block, the estimator's block, the timing the config
    derives from them and the stream watch's timeout (docs/harness.md, "Sync pairing", "What a read costs, and
    the block length")."""

    earth: Earth
    geometry: TableGeometry
    imu: Any  # the ``imu`` block (:class:`hil.config.ImuConfig`): protocol, options, baudrate, calibration
    turntable: Any  # the ``turntable`` block: data protocol, baudrate, limits, timing
    estimator: Any  # the ``estimator`` block
    imu_rate_hz: float  # the sync pulse train's rate and the IMU's
    table_counter_rate_hz: float  # counts per second of the table's sync counter
    table_counts_per_frame: int  # steps of that counter between two table frames
    block_samples: int  # samples the estimator takes at once
    reads_per_block: int  # live reads a block is split into
    read_s: float  # s between a live trial's reads
    stream_timeout_s: float  # s of bytes without a frame before the stream watch says what they are

    @classmethod
    def of(cls, cfg: Any) -> PipelineSettings:
        """The settings of a one-unit :class:`hil.config.Config`."""
        earth = Earth.from_config(cfg.site)
        return cls(earth, TableGeometry.from_config(cfg.turntable), cfg.imu, cfg.turntable, cfg.estimator,
                   cfg.imu_rate_hz, cfg.table_counter_rate_hz, cfg.table_counts_per_frame, cfg.block_samples,
                   cfg.reads_per_block, cfg.read_s, cfg.output.stream_timeout_s)

    @property
    def free_running(self) -> bool:
        """Either device latches on its own clock: the streams are paired by time, not by the sync counters."""
        return self.imu.timing.free_running or self.turntable.timing.free_running

    @property
    def rate_limit_dps(self) -> float:
        """The table's highest axis rate limit (deg/s)."""
        return max(self.turntable.limits.rate_dps)

    def codecs(self) -> dict[str, Codec]:
        """New codecs of the IMU's and the table's data streams."""
        return {Stream.IMU: imu_codec(self.imu, self.imu_rate_hz),
                Stream.TABLE: data_codec(self.turntable, self.table_counts_per_frame)}
