"""The turntable's plug-ins by name: its data codec (``turntable.data_protocol``, from the codec registry) and
its controller. Controllers are found as the codecs are: one table plus the entry-point group
``turntable_hil.table_controllers``, whose entries name a :class:`drivers.table_controller.TableController`
subclass. A controller's class names its emulated table (``emulated_table = "module:Class"``) and its
options model (``Options``), which validates ``turntable.controller_options``.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Any

from pydantic import ValidationError

from hil.config import ConfigError, describe_validation
from hil.plugins import codec_class

CONTROLLERS: dict[str, tuple[str, str]] = {
    "acutrol": ("drivers.acutrol_controller", "AcutrolController"),
    "aerosmith": ("drivers.aerosmith_controller", "AerosmithController"),
}
ENTRY_POINT_GROUP = "turntable_hil.table_controllers"


def controller_names() -> list[str]:
    """The built-ins (sorted), then the entry points'."""
    return sorted(CONTROLLERS) + [ep.name for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name not in CONTROLLERS]


def controller_class(name: str) -> type:
    """The controller class registered under ``name``; :class:`ConfigError` naming the key when none is."""
    if name in CONTROLLERS:
        module, cls = CONTROLLERS[name]
        return getattr(importlib.import_module(module), cls)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == name:
            return ep.load()
    raise ConfigError(f"turntable.controller: {name!r} is not a known controller; known: "
                      f"{', '.join(controller_names())}")


def controller_options(table: Any) -> Any:
    """``turntable.controller_options`` validated by the controller's own model."""
    cls = controller_class(table.controller)
    try:
        return cls.Options.model_validate(table.controller_options)
    except ValidationError as exc:
        raise ConfigError(f"turntable.controller_options.{describe_validation(exc)} (controller "
                          f"{table.controller!r})") from None


def make_controller(table: Any, url: str) -> Any:
    """The controller a ``turntable`` config block asks for, on command port ``url`` (not yet open)."""
    return controller_class(table.controller)(url, table.limits, controller_options(table), table.baudrate)


def data_codec(table: Any, pulses_per_frame: int = 1) -> Any:
    """The codec of the table's data frames, ``turntable.data_protocol`` in the codec registry."""
    try:
        cls = codec_class(table.data_protocol)
    except KeyError as exc:
        raise ConfigError(f"turntable.data_protocol: {exc.args[0]}") from None
    if getattr(cls, "kind", None) != "table":
        raise ConfigError(f"turntable.data_protocol: {table.data_protocol!r} is not a turntable data protocol "
                          f"(its kind is {getattr(cls, 'kind', None)!r})")
    return cls(pulses_per_frame=pulses_per_frame)

