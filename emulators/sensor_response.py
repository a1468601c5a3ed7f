"""The emulated gyros' dynamics: a second-order low-pass on the sensed rate and a pure output delay.

The continuous truth is H(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2) e^{-s tau}, wn set so that |H| is -3 dB at
``imu.errors.bandwidth_hz``: f_3dB = f_n sqrt(1 - 2 zeta^2 + sqrt((1 - 2 zeta^2)^2 + 1)). The IMU's
increments are interval means of the rate, and so are the encoder's turns it is compared with; the filter
acts on that sequence. Its poles are the continuous ones mapped exactly (z = e^{sT}); its
``NUMERATOR_TAPS`` numerator taps are the least-squares fit of H(jw) A(e^{jwT}) from DC to a quarter of the
output rate (with the delay's fraction of a period and up to ``FOLDED_MAX`` of its whole periods in H, so that
the taps centre on it), scaled to unit gain at DC; the delay's other whole periods are a delay line. The
discrete response is then within 0.1 % in gain and 0.05 deg in phase of H(jw) up to twice a bandwidth of a
tenth of the rate, and a pure fractional delay of at least a period within 0.05 % and 0.02 deg up to a fifth
of the rate (tests/test_rate_tests.py). Stateful, starting at rest
on the first sample (the first output repeats it), so chunks give the output of one call on the whole series.
"""

from __future__ import annotations

import math

import numpy as np

NUMERATOR_TAPS = 12
FOLDED_MAX = 4  # whole periods of the delay the numerator takes on (its taps centred on them), the rest a line
FIT_BAND = 0.25  # of the output rate: the band the numerator is fitted over
FIT_POINTS = 400


def natural_frequency(bandwidth_hz: float, damping: float) -> float:
    """f_n (Hz) of the second-order low-pass whose -3 dB bandwidth is ``bandwidth_hz``."""
    c = 1.0 - 2.0 * damping**2
    return bandwidth_hz / math.sqrt(c + math.sqrt(c * c + 1.0))


def continuous_response(f: np.ndarray, bandwidth_hz: float | None, damping: float, delay_s: float) -> np.ndarray:
    """H(j 2 pi f) of the module docstring (no low-pass when ``bandwidth_hz`` is None)."""
    w = 2.0 * math.pi * np.asarray(f, dtype=float)
    h = np.exp(-1j * w * delay_s)
    if bandwidth_hz is not None:
        wn = 2.0 * math.pi * natural_frequency(bandwidth_hz, damping)
        h = h * wn**2 / (wn**2 - w**2 + 2j * damping * wn * w)
    return h


def discrete_filter(rate_hz: float, bandwidth_hz: float | None, damping: float, fraction: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the discrete low-pass and ``fraction`` periods of delay (module docstring)."""
    period = 1.0 / rate_hz
    if bandwidth_hz is None and fraction == 0.0:
        return np.array([1.0]), np.array([1.0])
    a = np.array([1.0])
    if bandwidth_hz is not None:
        wn = 2.0 * math.pi * natural_frequency(bandwidth_hz, damping)
        a = np.real(np.poly(np.exp(np.roots([1.0, 2.0 * damping * wn, wn * wn]) * period)))
    f = np.linspace(0.0, FIT_BAND * rate_hz, FIT_POINTS)
    z = np.exp(-2j * math.pi * f * period)  # z^-1
    target = continuous_response(f, bandwidth_hz, damping, fraction * period) * np.polyval(a[::-1], z)
    taps = np.column_stack([z**k for k in range(NUMERATOR_TAPS)])
    b = np.linalg.lstsq(np.vstack([taps.real, taps.imag]), np.concatenate([target.real, target.imag]), rcond=None)[0]
    return b * (a.sum() / b.sum()), a


class SensorResponse:
    """Applies the low-pass and the delay to increments (N, 3), chunk by chunk."""

    def __init__(self, rate_hz: float, bandwidth_hz: float | None, damping: float, delay_s: float) -> None:
        whole = math.floor(delay_s * rate_hz + 1e-9)
        fraction = delay_s * rate_hz - whole
        folded = min(whole, FOLDED_MAX) if bandwidth_hz is not None or fraction > 1e-9 else 0
        self._b, self._a = discrete_filter(rate_hz, bandwidth_hz, damping, fraction + folded)
        whole -= folded
        self._lfilter = self._lfilter_zi = None
        if len(self._b) > 1:  # scipy.signal here, not with the module nor at the first sample: ~1 s to import
            from scipy.signal import lfilter, lfilter_zi

            self._lfilter, self._lfilter_zi = lfilter, lfilter_zi
        self._whole = whole
        self._state: np.ndarray | None = None  # the filter's state (order, 3)
        self._line: np.ndarray | None = None  # the last ``whole`` filtered samples (whole, 3)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The increments as the sensor outputs them."""
        if not len(x):
            return x
        if self._state is None:
            zi = self._lfilter_zi(self._b, self._a) if self._lfilter_zi is not None else np.zeros(0)
            self._state = zi[:, None] * x[0]
            self._line = np.repeat(x[:1], self._whole, axis=0)
        if self._lfilter is not None:
            x, self._state = self._lfilter(self._b, self._a, x, axis=0, zi=self._state)
        joined = np.vstack([self._line, x])
        self._line = joined[len(joined) - self._whole:]
        return joined[: len(x)]
