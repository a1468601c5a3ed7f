"""Codec classes found by name, as python-can finds its interfaces: one table plus entry-point groups.

The table names each built-in by its module path and the entry points name a third party's class, so
the configuration (which sits below the drivers) can check ``imu.protocol`` and ``imu.options`` against
the codec itself: a name is resolved, and its module imported, only when it is looked up. A third party
adds an IMU with one module and one entry point in the group ``turntable_hil.imu_codecs`` naming its
:class:`drivers.codec.Codec` subclass (docs/devices.md); other codecs go in ``turntable_hil.codecs``.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Any

from pydantic import ValidationError

from hil.config_types import describe_validation

# name -> "module:class"
BUILT_IN: dict[str, str] = {
    "kvh1750": "drivers.kvh1750:Kvh1750Codec",
    "xsens-mtdata2": "drivers.xsens:XsensCodec",
    "can-dbc": "drivers.can_dbc:CanDbcCodec",
    "stim300": "drivers.stim300:Stim300Codec",
    "tts1": "drivers.tts1:Tts1Codec",
    "acl": "drivers.acl:AclCodec",
}
IMU_GROUP = "turntable_hil.imu_codecs"
GROUPS = (IMU_GROUP, "turntable_hil.codecs")


def _entry_points() -> list[Any]:
    """The installed entry points of every group, built-in names left out (a built-in cannot be replaced)."""
    return [ep for group in GROUPS for ep in entry_points(group=group) if ep.name not in BUILT_IN]


def codec_class(name: str) -> type:
    """The codec class registered under ``name``; KeyError naming the known protocols otherwise."""
    if name in BUILT_IN:
        module, cls = BUILT_IN[name].split(":")
        return getattr(importlib.import_module(module), cls)
    for ep in _entry_points():
        if ep.name == name:
            return ep.load()
    raise KeyError(f"protocol {name!r}: unknown; known protocols: {', '.join(protocol_names())}")


def protocol_names() -> list[str]:
    """Every registered protocol: the built-ins (sorted), then the entry points'."""
    return sorted(BUILT_IN) + list(dict.fromkeys(ep.name for ep in _entry_points()))


def imu_codec_class(name: str) -> type:
    """The class of IMU protocol ``name``; ValueError naming the IMU protocols when it is none."""
    try:
        cls = codec_class(name)
    except KeyError:
        cls = None
    if cls is None or getattr(cls, "kind", None) != "imu":
        imus = ", ".join(n for n in protocol_names() if getattr(_loaded(n), "kind", None) == "imu")
        what = "unknown" if cls is None else f"a {getattr(cls, 'kind', 'non-data')} protocol, not an IMU's"
        raise ValueError(f"{name!r}: {what}; IMU protocols: {imus}")
    return cls


def imu_options(name: str, options: dict[str, Any]) -> dict[str, Any]:
    """``options`` as IMU protocol ``name``'s own Options model validates them, its defaults filled in;
    ValueError naming the option and the protocol."""
    try:
        return imu_codec_class(name).Options.model_validate(options).model_dump()
    except ValidationError as exc:
        raise ValueError(f"{describe_validation(exc)} (the {name} options)") from None


def _loaded(name: str) -> type | None:
    """The class of ``name``, or None when it cannot be loaded (a broken plug-in is not listed)."""
    try:
        return codec_class(name)
    except Exception:  # an entry point's import may fail in any way
        return None
