"""Unit constants: multiply a value in the named unit to get SI (m/s^2, rad, rad/s, dimensionless)."""

from __future__ import annotations

import math

G0 = 9.80665  # m/s^2 per g (standard gravity)
UG = 9.80665e-6  # m/s^2 per micro-g (G0 * 1e-6, written out: the product rounds differently)
UG_PER_G2 = UG / G0**2  # 1/(m/s^2) per ug/g^2 (g the standard gravity, as in ug)
DEG = math.pi / 180.0  # rad per degree
DEG_PER_H = DEG / 3600.0  # rad/s per deg/h
ARCSEC = DEG / 3600.0  # rad per arc second
PPM = 1e-6
HOUR = 3600.0  # s per hour
SQRT_HOUR = 60.0  # sqrt(s) per sqrt(h)
DEG_PER_SQRT_H = DEG / SQRT_HOUR  # rad/sqrt(s) per deg/sqrt(h) (angle random walk)
DEG_PER_H_PER_SQRT_H = DEG_PER_H / SQRT_HOUR  # rad/s/sqrt(s) per deg/h/sqrt(h) (rate random walk)
PER_SQRT_H = 1.0 / SQRT_HOUR  # x/sqrt(s) per x/sqrt(h): m/s/sqrt(h) (velocity RW), m/s^2/sqrt(h)
