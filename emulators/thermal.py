"""The emulated IMU's temperature and its thermal errors (``imu.errors.thermal``).

The sensor's case follows the chamber's air through a first-order lag ``case_tau_s`` from the temperature it
starts at, and the electronics add ``self_heating_c`` after power-on with time constant ``warmup_tau_s``::

    T(t) = T_ch + (T_0 - T_ch) exp(-t / case_tau_s) + self_heating_c (1 - exp(-t / warmup_tau_s))

with t the trial time (the device powered at 0) and the chamber held at T_ch. With dT = T - reference_c, the
accelerometer bias is ``a1 dT + a2 dT^2`` (ug), the gyro bias ``g1 dT`` (deg/h), and each scale factor error
``s dT`` (ppm), per axis."""

from __future__ import annotations

import numpy as np

from hil.config_emulated import ThermalErrors
from hil.units import DEG_PER_H, PPM, UG


class ThermalModel:
    """The sensor's temperature and the thermal part of its errors, with the chamber at ``chamber_c`` and the
    sensor at ``start_c`` at trial time 0; ``period`` (s) is the sample interval."""

    def __init__(self, thermal: ThermalErrors, chamber_c: float, start_c: float, period: float) -> None:
        self.cfg, self.chamber_c, self.start_c, self.period = thermal, chamber_c, start_c, period

    def temperature_c(self, t: np.ndarray) -> np.ndarray:
        """The sensor's temperature (deg C) at trial times t (N,)."""
        c, t = self.cfg, np.asarray(t, dtype=float)
        case = self.chamber_c + (self.start_c - self.chamber_c) * np.exp(-t / c.case_tau_s)
        return case + c.self_heating_c * -np.expm1(-t / c.warmup_tau_s)

    def biases(self, temperature_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gyro rad/s, accel m/s^2) biases (N, 3) at the temperatures (N,)."""
        c, d = self.cfg, (np.asarray(temperature_c, dtype=float) - self.cfg.reference_c)[:, None]
        gyro = d * np.array(c.gyro_bias_dph_per_c) * DEG_PER_H
        accel = (d * np.array(c.accel_bias_ug_per_c) + d * d * np.array(c.accel_bias_ug_per_c2)) * UG
        return gyro, accel

    def errors(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The thermal errors (rad, m/s) added to ideal increments dtheta, dv (N, 3) over intervals ending at t."""
        temperature = self.temperature_c(t)
        d = (temperature - self.cfg.reference_c)[:, None]
        gyro, accel = self.biases(temperature)
        return (gyro * self.period + d * np.array(self.cfg.gyro_scale_ppm_per_c) * PPM * dtheta,
                accel * self.period + d * np.array(self.cfg.accel_scale_ppm_per_c) * PPM * dv)
