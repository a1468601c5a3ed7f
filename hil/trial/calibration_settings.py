"""What a calibration takes from a trial's config, read once by :meth:`CalibrationSettings.of` where the
calibration starts (:func:`hil.trial.calibration_runner.run_calibration`,
:func:`~hil.trial.calibration_runner.run_units_calibration`,
:func:`hil.trial.calibration_simulation.run_calibration_simulation`): the schedule's checks, the sequences, the
soaks, the live views and the fit receive these settings (or the one block they use), never the whole config."""

from __future__ import annotations

from dataclasses import dataclass

from hil.config import CalibrationConfig, Config, ImuErrors, TurntableConfig
from hil.config_environment import ChamberConfig
from hil.frames import Earth, TableGeometry


@dataclass(frozen=True)
class CalibrationSettings:
    """The ``calibration`` block, the table (its limits, its controller, its encoders' zero offsets), the site and
    the table's geometry, the IMU's sample rate, the fraction of a window's samples that may be missing, the chamber
    a simulated calibration over temperature models and, where the IMU's errors are the config's, those (the
    truth)."""

    calibration: CalibrationConfig
    turntable: TurntableConfig  # limits (deg/s, deg/s^2), controller, zero_offset_arcsec (the emulated encoders')
    earth: Earth
    geometry: TableGeometry
    imu_rate_hz: float  # the IMU's sample rate
    lacking_max: float  # fraction of a window's samples that may be missing (output.limits' missing and gated)
    chamber: ChamberConfig  # environment.chamber: the first-order model of a simulated calibration over temperature
    truth: ImuErrors | None  # the emulated or simulated IMU's errors; None for a real IMU

    @property
    def sample_period(self) -> float:
        """The IMU's sample interval (s)."""
        return 1.0 / self.imu_rate_hz

    @classmethod
    def of(cls, cfg: Config, simulated: bool = False) -> CalibrationSettings:
        """The settings of a one-unit :class:`hil.config.Config`; ``simulated``: its IMU is simulated in this
        process, its errors the truth whatever ``imu.source`` says."""
        limits = (cfg.limits.missing_max, cfg.limits.gated_max)
        lacking_max = 1.0 if limits == (None, None) else sum(v or 0.0 for v in limits)
        truth = cfg.imu.errors if simulated or cfg.imu.source == "emulator" else None
        return cls(cfg.calibration, cfg.turntable, Earth.from_config(cfg.site),
                   TableGeometry.from_config(cfg.turntable), cfg.imu_rate_hz, lacking_max, cfg.environment.chamber,
                   truth)
