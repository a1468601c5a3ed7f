"""Codec instances by name (the classes: :mod:`hil.plugins`, built-ins and entry points)."""

from __future__ import annotations

from typing import Any

from hil.plugins import codec_class


def make_codec(name: str, **options: Any) -> Any:
    """A codec instance, e.g. ``make_codec("kvh1750", rate_hz=1000, gyro_output="rate")`` or
    ``make_codec("tts1", pulses_per_frame=2)``."""
    return codec_class(name)(**options)


def imu_codec(imu: Any, rate_hz: float) -> Any:
    """The IMU codec an ``imu`` config block (:class:`hil.config.ImuConfig`) asks for."""
    return codec_class(imu.protocol).from_config(imu, rate_hz)
