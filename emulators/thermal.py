"""The emulated IMU's temperature and its thermal errors (``imu.errors.thermal``).

The sensor's case follows the chamber's air through a first-order lag ``case_tau_s`` from the temperature it
starts at, and the electronics add ``self_heating_c`` after power-on with time constant ``warmup_tau_s``::

    T(t) = T_ch + (T_0 - T_ch) exp(-t / case_tau_s) + self_heating_c (1 - exp(-t / warmup_tau_s))

with t the trial time (the device powered at 0; the self-heating's t counts from the last power-on where the
caller gives it) and the chamber held at T_ch; a chamber whose air moves is
taken as constant over each batch of samples (its value at the batch's first time), the case's lag carried
from batch to batch. With dT = T - reference_c, the
accelerometer bias is ``a1 dT + a2 dT^2`` (ug), the gyro bias ``g1 dT`` (deg/h), and each scale factor error
``s dT`` (ppm), per axis. They are added to the ideal increments, ahead of the triad's static scale factor S and
misalignment, so an axis puts them out times 1 + S: its scale factor at T is (1 + S)(1 + s dT) - 1, the truth a
calibration is judged against (:func:`hil.outputs.calibration_thermal.thermal_truth`)."""

from __future__ import annotations

import numpy as np

from collections.abc import Callable

from hil.config_emulated import ThermalErrors
from hil.units import DEG_PER_H, PPM, UG


class ThermalModel:
    """The sensor's temperature and the thermal part of its errors, with the chamber's air ``chamber(t)`` (deg C
    at trial time t) and the sensor's case at ``start_c`` at trial time 0; ``period`` (s) is the sample interval.
    Called on consecutive batches of times; a batch asked for again gets the same temperatures."""

    def __init__(self, thermal: ThermalErrors, chamber: Callable[[float], float], start_c: float,
                 period: float) -> None:
        self.cfg, self.chamber, self.period = thermal, chamber, period
        self._case_c, self._t = start_c, 0.0
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # the last batch's times and temperatures

    def temperature_c(self, t: np.ndarray, since_on: np.ndarray | None = None) -> np.ndarray:
        """The sensor's temperature (deg C) at trial times t (N,), the batch after the last one; ``since_on`` (N,)
        s since the device's last power-on (None: since trial time 0)."""
        c, t = self.cfg, np.asarray(t, dtype=float)
        if self._last is not None and np.array_equal(t, self._last[0]):
            return self._last[1]
        if not len(t):
            return t
        air = self.chamber(float(t[0]))
        case = air + (self._case_c - air) * np.exp(-(t - self._t) / c.case_tau_s)
        self._case_c, self._t = float(case[-1]), float(t[-1])
        on = t if since_on is None else np.asarray(since_on, dtype=float)
        self._last = (t.copy(), case + c.self_heating_c * -np.expm1(-on / c.warmup_tau_s))
        return self._last[1]

    def biases(self, temperature_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gyro rad/s, accel m/s^2) biases (N, 3) at the temperatures (N,)."""
        c, d = self.cfg, (np.asarray(temperature_c, dtype=float) - self.cfg.reference_c)[:, None]
        gyro = d * np.array(c.gyro_bias_dph_per_c) * DEG_PER_H
        accel = (d * np.array(c.accel_bias_ug_per_c) + d * d * np.array(c.accel_bias_ug_per_c2)) * UG
        return gyro, accel

    def errors(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray,
               since_on: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The thermal errors (rad, m/s) added to ideal increments dtheta, dv (N, 3) over intervals ending at t."""
        temperature = self.temperature_c(t, since_on)
        d = (temperature - self.cfg.reference_c)[:, None]
        gyro, accel = self.biases(temperature)
        return (gyro * self.period + d * np.array(self.cfg.gyro_scale_ppm_per_c) * PPM * dtheta,
                accel * self.period + d * np.array(self.cfg.accel_scale_ppm_per_c) * PPM * dv)
