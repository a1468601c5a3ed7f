"""``hil ratetest scale-factor|frequency-response``: the rate-table tests (docs/ratetests.md).

:func:`run_scale_factor` and :func:`run_frequency_response` take the trial's config and the test's settings
(a config's ``scale_factor`` / ``frequency_response``, or a plan step's) and read what the test uses once
(:class:`~hil.trial.ratetest_settings.RateTestSettings`), which the functions below them take; they check every
step against the table's limits before anything is sent, command the steps (:mod:`hil.trial.rate_steps`) and fit
the windows; they return the test's document (scale_factor.json, frequency_response.json), which
:func:`hil.outputs.ratetest.write_ratetest` writes with its figure, report and junit.xml.

The steps run by default in simulation (:func:`simulate_steps`, ``--simulate``): the emulated table's servo and
the emulated IMU in this process (as ``hil calibrate --simulate``, :mod:`emulators.servo_simulation`), every
command going through the controller's own formatting and parsing, simulated time advancing in blocks and the
sequence following the encoder's readings; or as a live trial (:func:`hil.trial.ratetest_live.live_steps`).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable

import numpy as np

from drivers.table_controller import InterlockError, LimitError, TableError
from emulators.servo_simulation import ServoSimulation
from hil.config import Config
from hil.config_ratetests import FrequencyResponseSettings, ScaleFactorSettings
from hil.estimation.frequency_response import DB, fit_response, model, response_at
from hil.estimation.rate_scale_factor import RatePoint, fit_scale_factor
from hil.outputs.result import COMPLETED, TrialEnd
from hil.samples import GIMBAL_AXES
from hil.trial.outcome import TrialSetupError
from hil.trial.rate_steps import RateSequence, RateStep, StepWindow, axis_in_body, placements
from hil.trial.ratetest_settings import RateTestSettings
from hil.units import DEG, DEG_PER_H, PPM

# Runs the steps ``plan(gimbals)`` makes (the table's gimbals given) on a trial's devices: the windows and how it ended
StepsRun = Callable[[Config, Callable[[tuple[str, ...]], list[RateStep]]], tuple[list[StepWindow], str]]
TABLE_SAMPLES_PER_CYCLE = 5  # the encoder's readings a cycle needs at least to be the reference
MIN_CYCLES = 10  # a frequency's window holds at least this many cycles
MARGIN = 0.95  # of the table's rate and acceleration limits an oscillation may use
ARRIVE_S = 5.0  # a step's nominal time to move and reach its motion, for the simulation's bound
BOUND_FACTOR, BOUND_S = 4.0, 60.0  # the simulation ends at this many times the steps' nominal length (+ s)
SCALE_FACTOR_KEYS = ("scale_factor_ppm", "scale_factor_sigma_ppm", "bias_dph", "bias_sigma_dph", "nonlinearity_ppm",
                     "nonlinearity_sigma_ppm", "asymmetry_ppm", "asymmetry_sigma_ppm", "asymmetry_signed_ppm",
                     "full_scale_dps")
LATCH_TOLERANCE = 0.05  # of an IMU period: a fitted delay within it (and 3 sigma) agrees with the stated latches
LACKING_MAX = 0.01  # a rate step's window lacking more of its samples is left out of the fit


def scale_factor_steps(settings: RateTestSettings, gimbals: tuple[str, ...]) -> list[RateStep]:
    """Both directions of every rate of ``settings.scale_factor`` about each gyro axis; TrialSetupError naming
    the key for a rate beyond the table's limit."""
    steps = []
    test = settings.scale_factor
    for gyro, angles, axis in _placements(settings, test.axes, gimbals, "scale_factor.axes"):
        limit = settings.limits.rate_dps[axis]
        for rate in test.rates_dps:
            if not 0.0 < rate <= limit:
                raise TrialSetupError(f"scale_factor.rates_dps: {rate:g} deg/s is beyond turntable.limits.rate_dps "
                                      f"of the {GIMBAL_AXES[axis]} axis ({limit:g} deg/s); nothing was sent")
            turns = max(1, math.floor(test.dwell_s * rate / 360.0))
            steps += [RateStep(gyro, angles, axis, turns * 360.0 / rate, test.settle_s, rate=sign * rate * DEG)
                      for sign in (1.0, -1.0)]
    return steps


def frequency_steps(settings: RateTestSettings, gimbals: tuple[str, ...]) -> list[RateStep]:
    """An oscillation at each frequency of ``settings.frequency_response`` about each gyro axis, its amplitude
    within the table's rate and acceleration limits; TrialSetupError naming the key for a frequency the IMU or
    the table cannot serve."""
    steps = []
    limits, test = settings.limits, settings.frequency_response
    for gyro, angles, axis in _placements(settings, test.axes, gimbals, "frequency_response.axes"):
        for f in sorted(test.frequencies_hz):
            w = 2.0 * math.pi * f
            if not 0.0 < f < settings.imu_rate_hz / 2.0:
                raise TrialSetupError(f"frequency_response.frequencies_hz: {f:g} Hz is not below half the IMU's "
                                      f"rate imu.rate_hz ({settings.imu_rate_hz:g} Hz); nothing was sent")
            if f * TABLE_SAMPLES_PER_CYCLE > settings.trial_rate_hz:
                raise TrialSetupError(f"frequency_response.frequencies_hz: {f:g} Hz: the table reports its angles at "
                                      f"trial.rate_hz ({settings.trial_rate_hz:g} Hz), fewer than "
                                      f"{TABLE_SAMPLES_PER_CYCLE} a cycle; nothing was sent")
            amplitude = min(test.amplitude_deg, MARGIN * limits.rate_dps[axis] / w,
                            MARGIN * limits.accel_dps2[axis] / w**2)
            if amplitude * w < test.min_rate_dps:
                raise TrialSetupError(
                    f"frequency_response.frequencies_hz: {f:g} Hz: turntable.limits.accel_dps2 of the "
                    f"{GIMBAL_AXES[axis]} axis ({limits.accel_dps2[axis]:g} deg/s^2) allows a rate amplitude of "
                    f"{amplitude * w:.3g} deg/s, below frequency_response.min_rate_dps ({test.min_rate_dps:g}); "
                    "nothing was sent")
            cycles = max(MIN_CYCLES, math.ceil(test.dwell_s * f))
            steps.append(RateStep(gyro, angles, axis, cycles / f, test.settle_s, amplitude=amplitude * DEG,
                                  frequency=f))
    return steps


def _placements(settings: RateTestSettings, axes: list[str], gimbals: tuple[str, ...], key: str) -> list:
    try:
        return placements(gimbals, settings.geometry, axes, key)
    except ValueError as exc:
        raise TrialSetupError(str(exc)) from None


def simulate_steps(cfg: Config, plan) -> tuple[list[StepWindow], str]:
    """Run the steps ``plan(gimbals)`` makes on the simulated table and IMU; the windows and how it ended."""
    sim = ServoSimulation.from_config(cfg)
    client = sim.command_client(cfg.turntable)
    rate = cfg.imu_rate_hz
    try:
        steps = plan(tuple(client.gimbals))  # refused before anything moves
        sequence = RateSequence(steps, client, 1.0 / rate)
        bound = BOUND_FACTOR * sum(s.window_s + s.settle_s + 2.0 * ARRIVE_S for s in steps) + BOUND_S
        client.apply_limits()
        sequence.start()
        while not sequence.done and sequence.failure is None and sim.samples < bound * rate:
            batch = sim.step(min(sim.samples + cfg.block_samples, bound * rate) / rate)
            sequence.feed(batch.t, batch.dtheta, batch.angles)
    except (TableError, LimitError, InterlockError) as exc:
        raise TrialSetupError(str(exc)) from None
    finally:
        try:
            client.close()
        except TableError as exc:
            print(f"hil: WARNING: could not confirm the turntable is off: {exc}", file=sys.stderr)
    if sequence.failure is not None:
        return [], str(TrialEnd.early(f"turntable is not moving as commanded: {sequence.failure}"))
    if not sequence.done:
        return [], str(TrialEnd.early(f"the steps did not end within {bound:.0f} s of simulated time "
                                      f"({sequence.progress})"))
    return sequence.windows(), COMPLETED


def _input_geometry(settings: RateTestSettings, step: RateStep) -> tuple[np.ndarray, float]:
    """The turning gimbal's unit vector in the body frame and the earth's rate about it (rad/s)."""
    geometry = settings.geometry
    direction = axis_in_body(geometry, step.angles, step.axis)
    c_bn = geometry.attitude_matrix(np.array(step.angles))[0][0]
    return direction, float(settings.earth.omega_n @ (c_bn @ direction))


def rate_point(settings: RateTestSettings, window: StepWindow, period: float) -> RatePoint:
    """A rate step's input (the encoder's whole turns over the window and the earth's rate about the axis, on
    the gyro) and the gyro's mean output with its 1-sigma (NaN for a window the pipeline took fewer than two
    samples of); saturated (:func:`saturation`) or not."""
    step = window.step
    gyro = window.dtheta[:, step.gyro] / period
    saturated = saturation(window, gyro, period, settings.scale_factor.gyro_range_dps)
    n = len(window.t)
    if n < 2:
        return RatePoint(step.rate, math.nan, math.nan, math.nan, saturated)
    direction, earth = _input_geometry(settings, step)
    table = float(np.sum(window.turn[:, step.axis]) / np.sum(window.dt))
    return RatePoint(step.rate, direction[step.gyro] * (table + earth), float(np.mean(gyro)),
                     float(np.std(gyro, ddof=1) / math.sqrt(n)), saturated)


def saturation(window: StepWindow, gyro: np.ndarray, period: float, range_dps: float | None) -> str | None:
    """Why a step's window is no measure of the gyro's scale factor: samples the IMU flagged invalid (the
    pipeline takes them out, as it does lost ones) beyond ``LACKING_MAX`` of its samples, or a sample at the
    gyro's range; None when it is one."""
    expected = round(window.step.window_s / period)
    lacking = expected - len(window.t)
    if lacking > max(1.0, LACKING_MAX * expected):
        return f"{lacking} of its {expected} samples flagged invalid by the IMU (a gyro clipping at its range) or lost"
    if range_dps is not None and np.max(np.abs(gyro)) >= (1.0 - 1e-6) * range_dps * DEG:
        return f"the gyro reads its range, {range_dps:g} deg/s (scale_factor.gyro_range_dps)"
    return None


def scale_factor_document(settings: RateTestSettings, windows: list[StepWindow], ended: str) -> dict:
    """scale_factor.json's document (docs/ratetests.md) of the windows."""
    period = 1.0 / settings.imu_rate_hz
    axes = {}
    for gyro in sorted({w.step.gyro for w in windows}):
        points = [rate_point(settings, w, period) for w in windows if w.step.gyro == gyro]
        axes["xyz"[gyro]] = _scale_factor_axis(points)
    doc = {"test": "scale_factor", "trial": {"name": settings.trial_name}, "ended": ended,
           "settings": settings.scale_factor.model_dump(), "axes": axes}
    if settings.truth is not None:
        e = settings.truth
        doc["truth"] = {"xyz"[k]: {"scale_factor_ppm": e.gyro_scale_ppm[k], "bias_dph": e.gyro_bias_dph[k],
                                   "asymmetry_ppm": abs(e.scale_asymmetry_ppm[k]),
                                   "asymmetry_signed_ppm": e.scale_asymmetry_ppm[k], "nonlinearity_ppm": 0.0}
                        for k in range(3)}
    return doc


def _scale_factor_axis(points: list[RatePoint]) -> dict:
    """One gyro's block of scale_factor.json: its fit (every figure null, ``unfitted`` saying why, when too few
    steps are left) and its steps, those left out named with the reason."""
    steps = [{"rate_dps": round(p.commanded / DEG, 9), "input_dps": _finite(p.input / DEG),
              "output_dps": _finite(p.output / DEG), "sigma_dph": _finite(p.sigma / DEG_PER_H),
              "saturated": p.saturated is not None, "left_out": p.saturated, "residual_ppm": None} for p in points]
    try:
        fit = fit_scale_factor(points)
    except ValueError as exc:
        return {**dict.fromkeys(SCALE_FACTOR_KEYS), "unfitted": str(exc), "steps": steps}
    for step, residual in zip((s for s in steps if not s["saturated"]), fit.residuals):
        step["residual_ppm"] = float(residual) / PPM
    figures = ((fit.scale - 1.0) / PPM, fit.scale_sigma / PPM, fit.bias / DEG_PER_H, fit.bias_sigma / DEG_PER_H,
               fit.nonlinearity / PPM, fit.nonlinearity_sigma / PPM, abs(fit.asymmetry) / PPM,
               fit.asymmetry_sigma / PPM, fit.asymmetry / PPM, fit.full_scale / DEG)
    return {**{key: float(value) for key, value in zip(SCALE_FACTOR_KEYS, figures)}, "unfitted": None, "steps": steps}


def _finite(value: float) -> float | None:
    """``value``, or None where it is not a number (a step's window without samples)."""
    return float(value) if math.isfinite(value) else None


def frequency_response_document(settings: RateTestSettings, windows: list[StepWindow], ended: str) -> dict:
    """frequency_response.json's document (docs/ratetests.md) of the windows."""
    period = 1.0 / settings.imu_rate_hz
    axes = {}
    for gyro in sorted({w.step.gyro for w in windows}):
        mine = [w for w in windows if w.step.gyro == gyro]
        f = np.array([w.step.frequency for w in mine])
        measured = []
        for w in mine:
            direction = axis_in_body(settings.geometry, w.step.angles, w.step.axis)
            table = w.turn[:, w.step.axis] * direction[gyro] / w.dt
            measured.append(response_at(w.t, w.dtheta[:, gyro] / period, table, w.step.frequency))
        ratio, sigma = np.array([m[0] for m in measured]), np.array([m[1] for m in measured])
        axes["xyz"[gyro]] = _response_axis(f, ratio, sigma, [w.step.amplitude / DEG for w in mine])
        axes["xyz"[gyro]]["latch_check"] = latch_check(settings, axes["xyz"[gyro]])
    doc = {"test": "frequency_response", "trial": {"name": settings.trial_name}, "ended": ended,
           "settings": settings.frequency_response.model_dump(), "axes": axes}
    if settings.truth is not None:
        e = settings.truth
        doc["truth"] = {"bandwidth_hz": e.bandwidth_hz, "damping": e.damping if e.bandwidth_hz else None,
                        "delay_ms": e.delay_ms}
    return doc


def latch_check(settings: RateTestSettings, axis: dict) -> str:
    """Whether the fitted delay agrees with the latch delays the config states: the aligner puts each sample at
    its device's stated latch, so a delay beyond 3 sigma (and ``LATCH_TOLERANCE`` of a period) is the IMU's
    output lagging what ``imu.latch_delay_us`` says, or the stated latch delays being off."""
    stated = (f"imu.latch_delay_us {settings.imu_latch_delay_us:g}, "
              f"turntable.latch_delay_us {settings.table_latch_delay_us:g}")
    delay, sigma = axis["delay_ms"], axis["delay_sigma_ms"]
    if abs(delay) <= 3.0 * sigma + LATCH_TOLERANCE * 1e3 / settings.imu_rate_hz:
        return f"agrees with the latch delays stated ({stated})"
    return (f"disagrees: the gyro {'lags' if delay > 0 else 'leads'} the encoder by {abs(delay):.3f} ms beyond the "
            f"latch delays stated ({stated}): the IMU's output delay, latch delays that are off, or streams paired a "
            "whole number of samples apart")


def _response_axis(f: np.ndarray, ratio: np.ndarray, sigma: np.ndarray, amplitudes: list[float]) -> dict:
    fit = fit_response(f, ratio, sigma)
    fitted = model(f, fit.natural, fit.damping, fit.delay)
    beyond = fit.bandwidth is None  # the band fixes neither the damping nor the bandwidth
    phase = np.degrees(np.unwrap(np.angle(ratio)))
    return {"frequencies_hz": f.tolist(), "amplitude_deg": amplitudes,
            "gain_db": (DB * np.log(np.abs(ratio))).tolist(), "gain_sigma_db": (DB * sigma).tolist(),
            "phase_deg": phase.tolist(), "phase_sigma_deg": np.degrees(sigma).tolist(),
            "model_gain_db": (DB * np.log(np.abs(fitted))).tolist(),
            "model_phase_deg": (phase + np.degrees(np.angle(fitted / ratio))).tolist(),
            "bandwidth_hz": fit.bandwidth, "bandwidth_sigma_hz": fit.bandwidth_sigma,
            "bandwidth_note": None if fit.bandwidth is not None else
            f"beyond the highest frequency tested ({fit.f_max:g} Hz)",
            "damping": None if beyond else fit.damping, "damping_sigma": None if beyond else fit.damping_sigma,
            "delay_ms": fit.delay * 1e3, "delay_sigma_ms": fit.delay_sigma * 1e3}


def run_scale_factor(cfg: Config, settings: ScaleFactorSettings, steps_run: StepsRun = simulate_steps) -> dict:
    """The scale factor test with ``settings``, its steps run by ``steps_run`` (by default in simulation, else
    e.g. :func:`hil.trial.ratetest_live.live_steps` with its trial's arguments); its document."""
    cfg = cfg.model_copy(update={"scale_factor": settings})
    rate_test = RateTestSettings.of(cfg)
    windows, ended = steps_run(cfg, lambda gimbals: scale_factor_steps(rate_test, gimbals))
    return scale_factor_document(rate_test, windows, ended)


def run_frequency_response(cfg: Config, settings: FrequencyResponseSettings,
                           steps_run: StepsRun = simulate_steps) -> dict:
    """The frequency response test with ``settings``, its steps run by ``steps_run``; its document."""
    cfg = cfg.model_copy(update={"frequency_response": settings})
    rate_test = RateTestSettings.of(cfg)
    windows, ended = steps_run(cfg, lambda gimbals: frequency_steps(rate_test, gimbals))
    return frequency_response_document(rate_test, windows, ended)
