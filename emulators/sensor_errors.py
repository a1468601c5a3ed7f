"""Sensor error model: ideal IMU increments -> measured increments.

Per interval k of length T = 1/rate_hz ending at t_k, with the interval-mean rate w = dtheta/T and
specific force f = dv/T (all per axis x, y, z; products and squares element-wise):

    1. misalignment and scale (three-stage self-calibration 2018, Eqs. (5)-(6)):
           w1 = (I + S_g) C_g w,          f1 = (I + S_a) C_a f
       then the gyros' scale asymmetry a (K+ = K (1 + a/2) for positive rates, K (1 - a/2) for negative),
           w1 <- w1 + (a/2) |w1|,
       the gyros' second-order low-pass and the output delay (both triads) of :mod:`emulators.sensor_response`
    2. quadratic nonlinearity, accelerometers only (Eq. (6), K_nl term, first order):
           f2 = f1 + K_nl f1^2
    3. bias: repeatability, linear drift (gravity-vector 2018, Eq. (90): b = b_s + k t, here averaged
       over the interval), random walk and white noise (1-sigma per sample, Liu 2019 Table 2):
           w3 = w1 + b_g + k_g (t_k - T/2) + r_g[k] + sigma_g n_g[k]
           f3 = f2 + b_a + k_a (t_k - T/2) + r_a[k] + sigma_a n_a[k]
       with r[k] = r[k-1] + q sqrt(T) m[k], r[0] = 0 (a Wiener process sampled per interval), n, m ~ N(0, 1);
       plus the bias instability, a sum of Gauss-Markov processes (``BiasInstability``)
    4. the gyros' range (``gyro_range_dps``): their output clipped at +- it, then
       output quantisation with the remainder carried to the next sample:
           dtheta_out = Q_dtheta(w3 T),   dv_out = Q_dv(f3 T)

Eq. (6) writes the ideal force through SF^-1 C_p^a; here SF^-1 = I + S with S = diag(scale factor
errors). C_p^a maps platform axes to the non-orthogonal sensor axes; its rows are the sensitive axes.
Sensor axis i is turned by beta_ij about platform axis j (right-handed; the signs that a plain-text
copy of Eq. (5) loses follow from that geometry):

    C = [[ 1,       beta_xz, -beta_xy],
         [-beta_yz, 1,        beta_yx],
         [ beta_zy, -beta_zx, 1      ]]

The same form is used for the gyros. The implicit Eq. (6), f_a = ... + K_nl (f_a - b)^2, is taken to
first order in K_nl: the square is of the misaligned, scaled force f1.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from emulators.sensor_response import SensorResponse
from emulators.thermal import ThermalModel
from hil.config import ConfigError, ImuErrors
from hil.units import ARCSEC, DEG, DEG_PER_H, HOUR, PPM, UG, UG_PER_G2

# Quantisation remainders are folded back to [-0.5, 0.5] quanta every this many samples (counted from the
# first sample) so that the running fractional sum keeps its precision over long trials.
_QUANT_BLOCK = 4096


def misalignment_matrix(angles_rad: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """C_p^a of the 2018 three-stage paper, Eq. (5), from angles ordered (xy, xz, yx, yz, zx, zy)."""
    xy, xz, yx, yz, zx, zy = angles_rad
    return np.array([[1.0, xz, -xy], [-yz, 1.0, yx], [zy, -zx, 1.0]])


class _Quantiser:
    """Rounds increments to whole quanta, carrying the remainder so that the output sum tracks the input sum."""

    def __init__(self, quantum: float) -> None:
        self._quantum = quantum
        self._carry = np.zeros(3)  # running sum of fractional parts, in quanta
        self._count = 0  # samples processed so far

    def __call__(self, x: np.ndarray) -> np.ndarray:
        u = x / self._quantum
        whole = np.rint(u)
        frac = u - whole  # exact; the carry only has to track these
        counts = np.empty_like(u)
        start = 0
        while start < len(u):
            stop = min(len(u), start + _QUANT_BLOCK - self._count % _QUANT_BLOCK)
            running = np.cumsum(np.vstack([self._carry, frac[start:stop]]), axis=0)
            counts[start:stop] = whole[start:stop] + np.diff(np.rint(running), axis=0)
            self._carry = running[-1]
            self._count += stop - start
            if self._count % _QUANT_BLOCK == 0:
                self._carry = self._carry - np.rint(self._carry)
            start = stop
        return counts * self._quantum


class BiasInstability:
    """Flicker bias: a sum of first-order Gauss-Markov processes, one column per coefficient B.

    Correlation times Tc_i = 0.1 s * 4^i, i = -2..11 (6.25 ms to 4.2e5 s), each process of variance
    s^2 = B^2 ln(4) / pi. Lorentzians of equal variance at log-spaced corners (ratio r) sum to a 1/f
    spectrum S(f) = s^2 / (ln(r) f), whose Allan variance is 2 ln2 s^2 / ln r = (2 ln2 / pi) B^2, the
    IEEE 952 floor (Eq. C.15), over the decades the corners span: the deviation is within 2 % of
    0.664 B from 0.11 s (and 10 sample periods) to 7.6e4 s (docs/noise.md). Sampled per interval T
    from the stationary state:
        b_i[k] = phi_i b_i[k-1] + sqrt(1 - phi_i^2) s e_i[k],  phi_i = exp(-T / Tc_i),  b_i[0] ~ N(0, s^2).
    Its own random stream (a child of the seed), so the other error kinds draw exactly as without it.
    """

    CORRELATION_TIMES = 0.1 * 4.0 ** np.arange(-2, 12)

    def __init__(self, coefficient: np.ndarray, period: float, seed: int) -> None:
        self._rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed).spawn(1)[0]))
        self._phi = np.exp(-period / self.CORRELATION_TIMES)
        sigma = np.asarray(coefficient, dtype=float) * math.sqrt(math.log(4.0) / math.pi)
        self._state = sigma * self._rng.standard_normal((len(self._phi), len(sigma)))
        self._drive = np.sqrt(1.0 - self._phi**2)[:, None] * sigma

    def __call__(self, n: int) -> np.ndarray:
        """The next n samples of the bias (n, columns), in the coefficients' unit."""
        # scipy.signal here, not with the module: ~1 s of start-up for trials without a bias instability
        from scipy import signal

        # Drawn sample-major, so that the stream does not depend on how the series is chunked.
        draws = self._rng.standard_normal((n,) + self._state.shape)
        total = np.zeros((self._state.shape[1], n))
        for i, phi in enumerate(self._phi):
            zi = phi * self._state[i][:, None]
            b = signal.lfilter([1.0], [1.0, -phi], self._drive[i][:, None] * draws[:, i].T, zi=zi)[0]
            if n:
                self._state[i] = b[:, -1]
            total += b
        return total.T


@dataclass(frozen=True)
class AxisErrors:
    """A triad's axes (steps 1 and 2 of the module docstring), SI: scale factor errors, misalignment angles
    (xy, xz, yx, yz, zx, zy), the quadratic nonlinearity (per m/s^2) and the scale asymmetry (None: none)."""

    scale: np.ndarray
    misalignment: np.ndarray
    nonlinearity: np.ndarray
    asymmetry: np.ndarray | None = None


@dataclass(frozen=True)
class RateErrors:
    """The errors a triad adds to its rate (step 3), SI: the bias, the white noise (1-sigma per sample), the
    linear drift (per s) and the random walk (per sqrt(s))."""

    bias: np.ndarray
    noise: np.ndarray
    drift: np.ndarray
    random_walk: np.ndarray


@dataclass(frozen=True)
class Output:
    """How a triad puts its rate out (steps 1 and 4): the quantum of an increment (0: none), the response
    (delay, low-pass; None: none) and the range, a rate (None: unlimited)."""

    quantum: float
    response: SensorResponse | None = None
    limit: float | None = None


class _Channel:
    """One sensor triad (gyros or accelerometers): static coefficients in SI and the random-walk state."""

    def __init__(self, axes: AxisErrors, rate: RateErrors, output: Output, period: float) -> None:
        self._limit = None if output.limit is None else output.limit * period  # the output's range, as an increment
        self.clipped: np.ndarray | None = None  # (N, 3) of the last call: where the output read its range
        asymmetry = axes.asymmetry
        self._asymmetry = None if asymmetry is None or not asymmetry.any() else asymmetry / 2.0
        self._response = output.response
        matrix = np.diag(1.0 + axes.scale) @ misalignment_matrix(axes.misalignment)
        self._matrix = None if np.array_equal(matrix, np.eye(3)) else matrix
        self._bias, self._noise, self._drift, self._nonlinearity = rate.bias, rate.noise, rate.drift, axes.nonlinearity
        self._walk_step = rate.random_walk * math.sqrt(period)
        self._walk = np.zeros(3)
        self._period = period
        self._quantise = _Quantiser(output.quantum) if output.quantum > 0.0 else None

    def __call__(
        self, t: np.ndarray, x: np.ndarray, white: np.ndarray, walk: np.ndarray, instability: np.ndarray | None
    ) -> np.ndarray:
        """Measured increments from ideal increments x (N, 3); white and walk are N(0, 1) draws (N, 3),
        instability the bias instability's rate (N, 3) or None."""
        period = self._period
        if self._matrix is not None:
            x = x @ self._matrix.T
        if self._asymmetry is not None:
            x = x + self._asymmetry * np.abs(x)  # K+ = K (1 + a/2), K- = K (1 - a/2)
        if self._response is not None:
            x = self._response(x)
        if self._nonlinearity.any():
            x = x + self._nonlinearity * x * x / period  # K f^2 T with f = x / T
        walk_state = np.cumsum(np.vstack([self._walk, self._walk_step * walk]), axis=0)[1:]
        if len(walk_state):
            self._walk = walk_state[-1]
        rate_error = self._bias + np.outer(t - period / 2.0, self._drift) + walk_state + self._noise * white
        if instability is not None:
            rate_error = rate_error + instability
        x = x + rate_error * period
        if self._limit is not None:
            self.clipped = np.abs(x) >= self._limit
            x = np.clip(x, -self._limit, self._limit)
        return self._quantise(x) if self._quantise is not None else x


def _response(errors: ImuErrors, rate_hz: float, lowpass: bool) -> SensorResponse | None:
    """The output delay (and, ``lowpass``, the gyros' low-pass) of :mod:`emulators.sensor_response`; None without."""
    bandwidth = errors.bandwidth_hz if lowpass else None
    if bandwidth is None and errors.delay_ms == 0.0:
        return None
    if bandwidth is not None and bandwidth > 0.1 * rate_hz:
        raise ConfigError(f"imu.errors.bandwidth_hz: {bandwidth:g} Hz is above a tenth of the IMU's output rate "
                          f"{rate_hz:g} Hz; the emulated low-pass holds its response up to twice its bandwidth only there")
    return SensorResponse(rate_hz, bandwidth, errors.damping, errors.delay_ms * 1e-3)


class SensorErrorModel:
    """Applies an IMU's errors (see the module docstring for the measurement equation) chunk by chunk.

    Stateful: successive calls on consecutive chunks give exactly the output of one call on the whole
    series (random-walk state, random stream and quantisation remainders carry over).
    """

    def __init__(self, errors: ImuErrors, rate_hz: float, seed: int, chamber_c: float | None = None) -> None:
        """``chamber_c``: the chamber's air (deg C) that ``errors.thermal`` follows (None: ``errors.temperature_c``)."""
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        period = 1.0 / rate_hz
        sqrt_hour = math.sqrt(HOUR)
        e = errors
        self._rng = np.random.Generator(np.random.PCG64(seed))
        self._gyro = _Channel(
            AxisErrors(np.array(e.gyro_scale_ppm) * PPM, np.array(e.gyro_misalignment_arcsec) * ARCSEC, np.zeros(3),
                       np.array(e.scale_asymmetry_ppm) * PPM),
            RateErrors(np.array(e.gyro_bias_dph) * DEG_PER_H, np.array(e.gyro_noise_dph) * DEG_PER_H,
                       np.array(e.gyro_drift_dph_per_h) * DEG_PER_H / HOUR,
                       np.array(e.gyro_random_walk_dph_per_sqrt_h) * DEG_PER_H / sqrt_hour),
            Output(e.dtheta_quantum_rad, _response(e, rate_hz, lowpass=True),
                   None if e.gyro_range_dps is None else e.gyro_range_dps * DEG),
            period,
        )
        self._accel = _Channel(
            AxisErrors(np.array(e.accel_scale_ppm) * PPM, np.array(e.accel_misalignment_arcsec) * ARCSEC,
                       np.array(e.accel_nonlinearity_ug_per_g2) * UG_PER_G2),
            RateErrors(np.array(e.accel_bias_ug) * UG, np.array(e.accel_noise_ug) * UG,
                       np.array(e.accel_drift_ug_per_h) * UG / HOUR,
                       np.array(e.accel_random_walk_ug_per_sqrt_h) * UG / sqrt_hour),
            Output(e.dv_quantum_mps, _response(e, rate_hz, lowpass=False)),
            period,
        )
        instability = np.concatenate(
            [np.array(e.gyro_bias_instability_dph) * DEG_PER_H, np.array(e.accel_bias_instability_ug) * UG]
        )
        self._gyro_instability, self._accel_instability = instability[:3].any(), instability[3:].any()
        self._instability = BiasInstability(instability, period, seed) if instability.any() else None
        self._temperature_c = e.temperature_c
        held_c = e.temperature_c if chamber_c is None else chamber_c
        self._chamber: Callable[[float], float] = lambda _t: held_c
        self._thermal = None if e.thermal is None else ThermalModel(e.thermal, self._chamber, e.temperature_c, period)

    @property
    def thermal(self) -> bool:
        """Whether the sensor's temperature moves (``imu.errors.thermal``), rather than being the configured one."""
        return self._thermal is not None

    def follow_chamber(self, air: Callable[[float], float]) -> None:
        """Take the chamber's air (deg C) at trial time t from ``air(t)``, called once a batch (an emulated
        chamber's time runs with the samples')."""
        self._chamber = air
        if self._thermal is not None:
            self._thermal.chamber = air

    def temperature_c(self, t: np.ndarray, since_on: np.ndarray | None = None) -> np.ndarray:
        """The sensor's temperature (deg C) at trial times t (N,): the configured constant, or the thermal model's
        (its self-heating from the last power-on, ``since_on`` s before each t, or from trial time 0)."""
        if self._thermal is not None:
            return self._thermal.temperature_c(t, since_on)
        if len(t):
            self._chamber(float(t[-1]))
        return np.full(len(t), self._temperature_c)

    def gyro_clipped(self) -> np.ndarray | None:
        """Per sample and axis of the last :meth:`apply` (N, 3), whether the gyro read its range
        (``gyro_range_dps``); None without a range."""
        return self._gyro.clipped

    def apply(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, accel_bias: np.ndarray | None = None,
              since_on: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Measured increments from ideal ones over consecutive intervals ending at t (N,).

        dtheta (N, 3) in rad and dv (N, 3) in m/s; returns (dtheta, dv) as measured, same shapes.
        ``accel_bias`` (N, 3) m/s^2: added to the accelerometers' bias (a power-on's turn-on bias); ``since_on``
        (N,): s since the last power-on, where the thermal model's self-heating counts from.
        """
        t = np.asarray(t, dtype=float)
        dtheta = np.asarray(dtheta, dtype=float)
        dv = np.asarray(dv, dtype=float)
        n = len(t)
        if t.shape != (n,) or dtheta.shape != (n, 3) or dv.shape != (n, 3):
            raise ValueError(
                f"expected t (N,), dtheta (N, 3) and dv (N, 3); got {t.shape}, {dtheta.shape}, {dv.shape}"
            )
        # A fixed number of draws per sample, in a fixed order, keeps the stream independent of chunking.
        draws = self._rng.standard_normal((n, 12))
        bias = self._instability(n) if self._instability is not None else np.zeros((n, 6))
        if self._thermal is not None:  # on the ideal increments, before the sensor's response and quantisation
            thermal_dtheta, thermal_dv = self._thermal.errors(t, dtheta, dv, since_on)
            dtheta, dv = dtheta + thermal_dtheta, dv + thermal_dv
        accel = bias[:, 3:] if self._accel_instability else None
        if accel_bias is not None:
            accel = accel_bias if accel is None else accel + accel_bias
        return (
            self._gyro(t, dtheta, draws[:, 0:3], draws[:, 6:9], bias[:, :3] if self._gyro_instability else None),
            self._accel(t, dv, draws[:, 3:6], draws[:, 9:12], accel),
        )
