"""Codecs found by name, as python-can finds its interfaces: one table plus an entry-point group.

A third party adds a protocol without touching this package by declaring an entry point in the
``turntable_hil.codecs`` group that names its :class:`drivers.codec.Codec` subclass.
"""

from __future__ import annotations

import importlib
import inspect
from importlib.metadata import entry_points
from typing import Any

# name -> (module, class)
CODECS: dict[str, tuple[str, str]] = {
    "kvh1750": ("drivers.kvh1750", "Kvh1750Codec"),
    "xsens-mtdata2": ("drivers.xsens", "XsensCodec"),
    "can-dbc": ("drivers.can_dbc", "CanDbcCodec"),
    "tts1": ("drivers.tts1", "Tts1Codec"),
    "acl": ("drivers.acl", "AclCodec"),
}
ENTRY_POINT_GROUP = "turntable_hil.codecs"


def codec_class(name: str) -> type:
    """The codec class registered under ``name``."""
    if name in CODECS:
        module, cls = CODECS[name]
        return getattr(importlib.import_module(module), cls)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == name:
            return ep.load()
    raise KeyError(f"protocol {name!r}: unknown; known protocols: {', '.join(protocol_names())}")


def protocol_names() -> list[str]:
    """Every registered protocol: the built-ins (sorted), then the entry points'."""
    return sorted(CODECS) + [ep.name for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name not in CODECS]


def make_codec(name: str, **options: Any) -> Any:
    """A codec instance, e.g. ``make_codec("kvh1750", rate_hz=1000, gyro_output="rate")``."""
    return codec_class(name)(**options)


def with_rate(cls: type, rate_hz: float, **options: Any) -> Any:
    """An instance of codec class ``cls``, given ``rate_hz`` when its constructor takes one."""
    takes_rate = "rate_hz" in inspect.signature(cls).parameters
    return cls(rate_hz=rate_hz, **options) if takes_rate else cls(**options)


def imu_codec(imu: Any, rate_hz: float) -> Any:
    """The IMU codec an ``imu`` config block (:class:`hil.config.ImuConfig`) asks for."""
    return codec_class(imu.protocol).from_config(imu, rate_hz)
