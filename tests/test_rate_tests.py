"""The rate-table tests' emulated truth (scale asymmetry, low-pass, delay), the scale-factor and frequency-response
runs in simulation against it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from emulators.sensor_errors import SensorErrorModel
from emulators.sensor_response import continuous_response
from hil.config import ConfigError, ImuErrors

RATE = 1000.0
T = 1.0 / RATE


def _gyro(errors: dict, dtheta: np.ndarray, chunks: int = 3) -> np.ndarray:
    """The gyro increments the error model makes of ideal ones (N, 3), fed in ``chunks`` pieces."""
    model = SensorErrorModel(ImuErrors(**errors), RATE, 1)
    t = np.arange(1, len(dtheta) + 1) * T
    parts = np.array_split(np.arange(len(t)), chunks)
    return np.vstack([model.apply(t[p], dtheta[p], np.zeros((len(p), 3)))[0] for p in parts])


def _phasor(x: np.ndarray, f: float) -> complex:
    """The complex amplitude of x at frequency f (least squares on cos, sin and a constant)."""
    k = np.arange(len(x)) * T * 2.0 * math.pi * f
    c = np.linalg.lstsq(np.column_stack([np.cos(k), np.sin(k), np.ones_like(k)]), x, rcond=None)[0]
    return complex(c[0], -c[1])


@pytest.mark.parametrize("f", [20.0, 100.0, 200.0])
def test_emulated_low_pass_and_delay_follow_the_continuous_transfer_function(f):
    rate = 0.5 * np.sin(2.0 * math.pi * f * np.arange(1, 6001) * T)  # rad/s, interval means
    out = _gyro({"bandwidth_hz": 100.0, "damping": 0.7, "delay_ms": 2.5}, np.outer(rate * T, np.ones(3)))
    ratio = _phasor(out[3000:, 1] / T, f) / _phasor(rate[3000:], f)
    truth = continuous_response(np.array([f]), 100.0, 0.7, 2.5e-3)[0]
    assert abs(abs(ratio) / abs(truth) - 1.0) < 2e-3
    assert abs(math.degrees(np.angle(ratio / truth))) < 0.15


def test_emulated_low_pass_is_minus_3_db_at_its_bandwidth():
    rate = np.sin(2.0 * math.pi * 100.0 * np.arange(1, 6001) * T)
    out = _gyro({"bandwidth_hz": 100.0, "damping": 0.7}, np.outer(rate * T, np.ones(3)))
    gain_db = 20.0 * math.log10(abs(_phasor(out[3000:, 0], 100.0) / _phasor(rate[3000:] * T, 100.0)))
    assert gain_db == pytest.approx(-10.0 * math.log10(2.0), abs=0.01)


def test_emulated_delay_of_whole_periods_repeats_the_input_that_many_samples_later():
    rng = np.random.default_rng(3)
    dtheta = rng.normal(size=(500, 3)) * 1e-4
    out = _gyro({"delay_ms": 2.0}, dtheta, chunks=7)
    np.testing.assert_allclose(out[2:], dtheta[:-2], rtol=0, atol=1e-18)
    np.testing.assert_allclose(out[:2], dtheta[[0, 0]], rtol=0, atol=1e-18)  # at rest on the first sample before


def test_scale_asymmetry_scales_positive_and_negative_rates_apart():
    dtheta = np.array([[1.0, -1.0, 0.5], [-1.0, 1.0, -0.5]]) * T
    out = _gyro({"scale_asymmetry_ppm": [200.0, 200.0, 0.0], "gyro_scale_ppm": [100.0, 0.0, 0.0]}, dtheta, chunks=1)
    k_plus, k_minus = out[0, 0] / dtheta[0, 0], out[1, 0] / dtheta[1, 0]
    assert (k_plus - k_minus) / ((k_plus + k_minus) / 2.0) == pytest.approx(200e-6, rel=1e-9)
    assert (k_plus + k_minus) / 2.0 == pytest.approx(1.0 + 100e-6, rel=1e-12)
    assert out[0, 2] == dtheta[0, 2]


def test_emulated_bandwidth_beyond_a_tenth_of_the_rate_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"imu\.errors\.bandwidth_hz: 150 Hz"):
        SensorErrorModel(ImuErrors(bandwidth_hz=150.0), RATE, 0)
