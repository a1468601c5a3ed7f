"""The calibration over temperature (``calibration.temperatures_c``): at each chamber set point in turn a soak
(:class:`~hil.trial.calibration_soak.Soak`, the table held at the schedule's first position), then the whole
schedule (:class:`~hil.trial.calibration_sequence.CalibrationSequence`), its windows kept with the IMU's temperature
over them (:func:`window_temperatures`: the sensor may still drift a little through a schedule, and each term is
estimated from some of its windows). A listener of the pipeline as the one-temperature sequence is, with the same
:attr:`done`, :attr:`failure` and :attr:`progress`; a soak's failure is :attr:`soak_failure` (the table moved
as commanded: the chamber or the sensor did not)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hil.config import CalibrationConfig
from hil.estimation.calibration_model import Window
from hil.estimation.calibration_schedule import Schedule
from hil.pipeline.progress import Progress
from hil.samples import GIMBAL_AXES
from hil.trial.calibration_sequence import CalibrationSequence
from hil.trial.calibration_soak import Soak
from hil.units import DEG


def window_temperatures(trace: np.ndarray, spans: list[tuple[float, float]], windows: list[Window]) -> dict:
    """The IMU's temperature (deg C) that each kind of term's estimate stands for, from the schedule's ``trace``
    ((N, 2): trial times s and the temperature of the read ending at each, the latest at a time taken, at the
    read's middle) and its ``windows`` over their ``spans`` (start, end s), each window at its mean temperature:
    ``dwells_c`` the dwells' (the accelerometers' terms), ``windows_c`` every window's (the gyros' other terms),
    both weighted by their samples, and ``gyro_scale_c`` per axis the plateaus' weighted by samples times the
    squared rate on that axis (a scale factor's information), ``windows_c`` where no window informs. A trace of
    one read gives its temperature to every window, an empty one NaN."""
    times, latest = np.unique(trace[::-1, 0], return_index=True)
    values = trace[::-1, 1][latest]
    if len(times) > 1:
        times, values = times[1:] - 0.5 * np.diff(times), values[1:]
    at = np.array([np.mean(np.interp(np.linspace(start, end, 64), times, values)) if len(times) else np.nan
                   for start, end in spans])
    samples = np.array([w.samples for w in windows], dtype=float)
    static = np.array([w.static for w in windows])
    every = float(np.average(at, weights=samples))

    def mean(weights: np.ndarray) -> float:
        return float(np.average(at, weights=weights)) if weights.any() else every

    information = samples[:, None] * np.array([w.angular_rate for w in windows]) ** 2 * ~static[:, None]
    return {"dwells_c": mean(samples * static), "windows_c": every, "gyro_scale_c": [mean(w) for w in information.T]}


@dataclass(frozen=True)
class TemperaturePoint:
    """One temperature's completed schedule (its windows: ``sequence.windows()``), the IMU's mean temperature
    (deg C) over it, its ``trace`` ((N, 2): trial time s, the IMU's temperature) and its soak's figures
    (:meth:`~hil.trial.calibration_soak.Soak.record`)."""

    imu_c: float
    sequence: CalibrationSequence
    soak: dict
    trace: np.ndarray

    def record(self) -> dict:
        """calibration.json's ``thermal.temperatures`` entry but the terms, with its windows' temperatures
        (:func:`window_temperatures`)."""
        spans = [(w.start, w.end) for w in self.sequence.windows_found]
        return {**self.soak, "imu_c": self.imu_c, **window_temperatures(self.trace, spans, self.sequence.windows())}


class ThermalSequence:
    """Soak and schedule at each of ``calibration.temperatures_c`` through the table ``client`` and the
    ``chamber`` controller; ``sequence(schedule)`` makes each temperature's
    :class:`~hil.trial.calibration_sequence.CalibrationSequence`."""

    def __init__(self, calibration: CalibrationConfig, schedule: Schedule, client, chamber,
                 sequence: Callable[[Schedule], CalibrationSequence]) -> None:
        self.temperatures = list(calibration.temperatures_c)
        self.settings = calibration.soak
        self.schedule, self.client, self.chamber, self.make = schedule, client, chamber, sequence
        self.points: list[TemperaturePoint] = []
        self.soak: Soak | None = None
        self.sequence: CalibrationSequence | None = None
        self.soak_failure: str | None = None
        self._temperatures: list[tuple[float, float]] = []  # (trial time, the IMU's) over the current schedule

    @property
    def done(self) -> bool:
        return len(self.points) == len(self.temperatures)

    @property
    def failure(self) -> str | None:
        """The current schedule's failure (the table did not move as commanded)."""
        return None if self.sequence is None else self.sequence.failure

    @property
    def progress(self) -> str:
        """Where the calibration is, for the console and an early end's reason."""
        if self.done:
            return f"all {len(self.temperatures)} temperatures done"
        if self.sequence is not None:
            step = self.sequence.progress
        else:
            step = self.soak.state if self.soak is not None else "not started"
        return f"temperature {len(self.points) + 1} of {len(self.temperatures)}, {step}"

    def report_rest(self) -> None:
        """End of data: the current schedule's windows not shown yet
        (:meth:`~hil.trial.calibration_sequence.CalibrationSequence.report_rest`)."""
        if self.sequence is not None:
            self.sequence.report_rest()

    def start(self) -> None:
        """The first soak."""
        self._soak(0.0)

    def on_progress(self, progress: Progress) -> None:
        """A listener of the pipeline: the soak, then the schedule, of the current temperature."""
        if self.done or self.soak_failure is not None:
            return
        if self.sequence is None:
            self.soak_update(progress.trial_time, progress.temperature_c)
            return
        if progress.temperature_c is not None:
            self._temperatures.append((progress.trial_time, progress.temperature_c))
        self.sequence.on_progress(progress)
        if self.sequence.done:
            self.sequence.report_rest()  # its samples end here: its last window is shown as the fit will take it
            trace = np.array(self._temperatures).reshape(-1, 2)
            self.points.append(TemperaturePoint(float(np.mean(trace[:, 1])) if len(trace) else float("nan"),
                                                self.sequence, self.soak.record(), trace))
            self.sequence, self._temperatures = None, []
            if not self.done:
                self._soak(progress.trial_time)

    @property
    def soaking(self) -> bool:
        """A soak is under way: the chamber or the sensor still settling, the table held."""
        return not self.done and self.soak_failure is None and self.sequence is None and self.soak is not None

    def soak_update(self, t: float, imu_c: float | None) -> None:
        """The soak at trial time ``t`` (s) with the IMU's latest temperature (deg C, None: none reported); the
        schedule started once it is over."""
        self.soak.update(t, imu_c)
        self.soak_failure = self.soak.failure
        if self.soak.done:
            self.sequence = self.make(self.schedule)
            self.sequence.start()

    def _soak(self, t: float) -> None:
        """The table to the schedule's first position, the chamber to the next temperature."""
        first = (list(self.schedule.dwells) + list(self.schedule.plateaus))[0]
        for k, gimbal in enumerate(GIMBAL_AXES):
            if gimbal in self.client.gimbals:
                self.client.demand_position(gimbal, first.angles[k] / DEG)
                self.client.set_mode(gimbal, "position")
        self.soak = Soak(self.temperatures[len(self.points)], self.settings, self.chamber, t)
