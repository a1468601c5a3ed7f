"""The turntable's plug-ins as its config block names them: its controller (:data:`drivers.registry.TABLE_CONTROLLERS`,
``turntable.controller``) with its options, and the codec of its data frames (:data:`drivers.registry.TABLE_CODECS`,
``turntable.data_protocol``). The config has checked both names and the options through the registries."""

from __future__ import annotations

from typing import Any

from drivers.registry import TABLE_CODECS, TABLE_CONTROLLERS


def controller_options(table: Any) -> Any:
    """``turntable.controller_options`` as the controller's own model holds them."""
    return TABLE_CONTROLLERS.options(table.controller, table.controller_options)


def make_controller(table: Any, url: str) -> Any:
    """The controller a ``turntable`` config block asks for, on command port ``url`` (not yet open)."""
    return TABLE_CONTROLLERS.get(table.controller)(url, table.limits, controller_options(table), table.baudrate)


def data_codec(table: Any, pulses_per_frame: int = 1) -> Any:
    """The codec of the table's data frames."""
    return TABLE_CODECS.get(table.data_protocol)(pulses_per_frame=pulses_per_frame)
