"""The rate-table tests' settings (``scale_factor`` and ``frequency_response`` in a trial config, or a plan
step's arguments): what the table is commanded to do. docs/ratetests.md."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from hil.config_types import Model

GyroAxis = Literal["x", "y", "z"]
Positive = Annotated[float, Field(gt=0)]


class ScaleFactorSettings(Model):
    """Rate steps in both directions about each gyro axis in turn."""

    rates_dps: list[Positive] = Field([10.0, 30.0, 60.0, 90.0], min_length=2)  # magnitudes; each is turned both ways
    dwell_s: float = Field(10.0, gt=0)  # each step's window: the whole turns that fit in it (at least one)
    settle_s: float = Field(1.0, ge=0)  # after the rate is reached, before the window
    axes: list[GyroAxis] = ["x", "y", "z"]  # gyro axes tested (a single-axis table: those on its axis)
    gyro_range_dps: float | None = Field(None, gt=0)  # the gyros' range: a step reading it is saturated; None: unknown


class FrequencyResponseSettings(Model):
    """Sinusoidal table motion at each frequency about each gyro axis in turn."""

    frequencies_hz: list[Positive] = Field([1.0, 2.0, 5.0, 10.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 150.0],
                                        min_length=3)
    amplitude_deg: float = Field(1.0, gt=0)  # at most; less where the table's rate or acceleration limit needs
    dwell_s: float = Field(2.0, gt=0)  # each frequency's window: the whole cycles that fit in it (at least 10)
    settle_s: float = Field(0.5, ge=0)  # after the oscillation starts, before the window
    min_rate_dps: float = Field(1.0, gt=0)  # a frequency whose rate amplitude the limits hold below this is refused
    axes: list[GyroAxis] = ["x", "y", "z"]
