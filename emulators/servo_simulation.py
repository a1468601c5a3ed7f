"""The emulated IMU and the commanded table in the caller's process, without transports (``hil calibrate
--simulate``).

The harness commands the servo (:mod:`emulators.servo`) through the configured controller on a
:class:`~emulators.table_server.ServoPort` (:meth:`ServoSimulation.command_client`), and :meth:`ServoSimulation.step`
advances simulated time: the samples up to a time under the servo's plan so far, which it then commits, so a
command sent after a step takes effect at the next sync pulse, as the emulator's pulse loop makes it.

As in :class:`emulators.simulation.Simulation`, sample k covers ((k - 1) / rate, k / rate]: its increments
are the truth's exact integrals with the sensor errors applied; its table angles are what the table reports
for that instant (:func:`emulators.sources.encoder_reading`: the zero offset, the 1e-6 deg grid), as the
aligner puts the table's readings on the IMU's instants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from drivers.controllers import make_controller
from drivers.table_controller import TableController
from emulators.sensor_errors import SensorErrorModel
from emulators.servo import Servo
from emulators.simulation import emulated_world
from emulators.sources import encoder_reading
from emulators.table_server import ServoPort, emulated_table
from emulators.truth import Truth
from hil.config import Config
from hil.samples import AlignedBatch, ImuGap
from hil.units import ARCSEC

IN_PROCESS = "emulator (in process)"  # the command client's url, for its messages


@dataclass
class ServoSimulation:
    """Truth, sensor errors and the servo of one trial; :attr:`samples` emitted so far."""

    truth: Truth
    errors: SensorErrorModel
    servo: Servo
    table: object  # the emulated table of turntable.controller, on the servo
    zero_offset: np.ndarray  # rad (outer, middle, inner): true angle minus encoder reading
    rate_hz: float
    samples: int = 0

    @classmethod
    def from_config(cls, cfg: Config) -> ServoSimulation:
        truth, errors = emulated_world(cfg)
        servo = Servo(cfg.turntable, cfg.imu_rate_hz, truth.motion)
        return cls(truth, errors, servo, emulated_table(cfg, servo), np.array(cfg.turntable.zero_offset_arcsec) * ARCSEC, cfg.imu_rate_hz)

    def __post_init__(self) -> None:
        self.port = ServoPort(self.table)

    def command_client(self, turntable) -> TableController:
        """The configured controller (``turntable``: :class:`hil.config.TurntableConfig`), open on :attr:`port`."""
        return make_controller(turntable, IN_PROCESS).open(self.port)

    def step(self, t_end: float) -> AlignedBatch:
        """The samples after those emitted that end at or before ``t_end`` (s), under the servo's plan; the
        servo's horizon is then their end."""
        t, t0 = self._instants(t_end), self.samples / self.rate_hz
        if not len(t):
            return AlignedBatch(t, np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)), t0)
        truth = self._advance(t)
        dtheta, dv = truth.increments(t0, t)
        dtheta, dv = self.errors.apply(t, dtheta, dv)
        self.samples += len(t)
        return AlignedBatch(t, dtheta, dv, encoder_reading(truth.angles(t), self.zero_offset), t0,
                            temperature_c=self.errors.temperature_c(t) if self.errors.thermal else None)

    def idle(self, t_end: float) -> np.ndarray | None:
        """The sensor's temperatures (deg C; None without a thermal model) at the instants of the samples
        :meth:`step` would emit up to ``t_end`` (s), the samples not made: the servo, the chamber and the sensor's
        temperature move on exactly as under :meth:`step`, its random errors draw nothing (a soak's wait)."""
        t = self._instants(t_end)
        if not len(t):
            return None
        self._advance(t)
        self.samples += len(t)
        return self.errors.temperature_c(t) if self.errors.thermal else None

    def gap(self, t_start: float) -> ImuGap:
        """The samples not made from trial time ``t_start`` (s) to the last instant reached, with the table's
        readings at both ends: the estimator carries its attitude across it (:meth:`idle`)."""
        motion = replace(self.truth, motion=self.servo.motion)
        ends = np.array([t_start, self.samples / self.rate_hz])
        start, end = encoder_reading(motion.angles(ends), self.zero_offset)
        return ImuGap(float(ends[0]), float(ends[1]), tuple(map(float, start)), tuple(map(float, end)))

    def _instants(self, t_end: float) -> np.ndarray:
        """The times (s) of the samples after those emitted that end at or before ``t_end``."""
        n = max(math.floor(t_end * self.rate_hz + 1e-9), self.samples)
        return np.arange(self.samples + 1, n + 1) / self.rate_hz

    def _advance(self, t: np.ndarray) -> Truth:
        """The servo moved on to the last of ``t`` and committed there; the truth under its plan."""
        with self.servo.lock:
            self.servo.advance(float(t[-1]))
            truth = replace(self.truth, motion=self.servo.motion)
            self.servo.commit(float(t[-1]))
        return truth
