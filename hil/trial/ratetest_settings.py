"""What the rate-table tests take from a trial's config, read once by :meth:`RateTestSettings.of` where a test
starts (:func:`hil.trial.ratetest_runner.run_scale_factor`, :func:`~hil.trial.ratetest_runner.run_frequency_response`):
the steps, their fits and the documents receive these settings, never the whole config."""

from __future__ import annotations

from dataclasses import dataclass

from hil.config import Config, ImuErrors, LimitsConfig
from hil.config_ratetests import FrequencyResponseSettings, ScaleFactorSettings
from hil.frames import Earth, TableGeometry


@dataclass(frozen=True)
class RateTestSettings:
    """The trial's name, the site, the table's geometry and limits, the IMU's and the table's rates, the latch
    delays the config states, both tests' settings and, for an emulated IMU, its configured errors (the truth)."""

    trial_name: str
    earth: Earth
    geometry: TableGeometry
    limits: LimitsConfig  # the table's rate (deg/s) and acceleration (deg/s^2) limits per axis
    imu_rate_hz: float  # the IMU's sample rate
    trial_rate_hz: float  # the rate the table reports its angles at
    imu_latch_delay_us: float  # imu.latch_delay_us
    table_latch_delay_us: float  # turntable.latch_delay_us
    scale_factor: ScaleFactorSettings
    frequency_response: FrequencyResponseSettings
    truth: ImuErrors | None  # the emulated IMU's errors; None for a real IMU

    @classmethod
    def of(cls, cfg: Config) -> RateTestSettings:
        """The settings of a one-unit :class:`hil.config.Config`."""
        return cls(cfg.trial.name, Earth.from_config(cfg.site),
                   TableGeometry.from_config(cfg.turntable), cfg.turntable.limits, cfg.imu_rate_hz, cfg.trial.rate_hz,
                   cfg.imu.latch_delay_us, cfg.turntable.latch_delay_us, cfg.scale_factor, cfg.frequency_response,
                   cfg.imu.errors if cfg.imu.source == "emulator" else None)
