"""Plug-ins by name, one registry per kind, as python-can finds its interfaces: the built-ins plus the installed
entry points of the kind's group (docs/devices.md, "Adding a plug-in").

| registry | config key | entry-point group |
| --- | --- | --- |
| :data:`IMU_CODECS` | ``imu.protocol`` | ``turntable_hil.imu_codecs`` |
| :data:`TABLE_CODECS` | ``turntable.data_protocol`` | ``turntable_hil.codecs`` |
| :data:`TABLE_CONTROLLERS` | ``turntable.controller`` | ``turntable_hil.table_controllers`` |
| :data:`CHAMBERS` | ``environment.chamber.controller`` | ``turntable_hil.chambers`` |
| :data:`POWER_SUPPLIES` | ``environment.power.controller`` | ``turntable_hil.power_supplies`` |

A plug-in is one class: its ``name``, its options model ``Options`` (which validates the config's options of the
plug-in) and, where the harness emulates it, ``emulated`` ("module:Class" of its emulated counterpart, found by
the plug-in's name: :meth:`Registry.emulated`). A built-in's module is imported only when its name is looked up,
and a built-in name cannot be taken by an entry point. An unknown name is one error form wherever it is met:
``<key>: '<name>': unknown; <the kind>: <the known names>``. The config asks a registry through the validators
it hands out (:meth:`Registry.name_check`, :meth:`Registry.options_check`); drivers know nothing of the config.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any

from pydantic import AfterValidator, ValidationError, ValidationInfo

from hil.config_types import describe_validation
from hil.vocabulary import Stream

CODEC_GROUPS = ("turntable_hil.imu_codecs", "turntable_hil.codecs")
CODECS_BUILT_IN = {  # name -> "module:Class"
    "kvh1750": "drivers.kvh1750:Kvh1750Codec",
    "xsens-mtdata2": "drivers.xsens:XsensCodec",
    "can-dbc": "drivers.can_dbc:CanDbcCodec",
    "stim300": "drivers.stim300:Stim300Codec",
    "tts1": "drivers.tts1:Tts1Codec",
    "acl": "drivers.acl:AclCodec",
}


def load(spec: str) -> Any:
    """The object a ``"module:name"`` string names."""
    module, _, name = spec.partition(":")
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True)
class Registry:
    """The plug-ins of one kind: ``built_in`` (name -> "module:Class") and the entry points of ``groups``; with
    ``kind``, only the classes whose ``kind`` attribute says so (the codecs of one device)."""

    plural: str  # what the kind's plug-ins are called in an error: "IMU protocols", "chamber controllers", ...
    groups: tuple[str, ...]
    built_in: Mapping[str, str]
    kind: str | None = None

    def _entry_points(self) -> dict[str, Any]:
        """The installed entry points of the groups by name, built-in names left out."""
        return {ep.name: ep for group in self.groups for ep in entry_points(group=group)
                if ep.name not in self.built_in}

    def _find(self, name: str) -> type | None:
        """The class registered as ``name`` whatever its kind, or None."""
        if name in self.built_in:
            return load(self.built_in[name])
        found = self._entry_points().get(name)
        return None if found is None else found.load()

    def _of_kind(self, cls: type | None) -> bool:
        return cls is not None and (self.kind is None or getattr(cls, "kind", None) == self.kind)

    def names(self) -> list[str]:
        """Every registered name: the built-ins (sorted), then the entry points'; a plug-in of another kind, or one
        that cannot be loaded, is left out."""
        names = sorted(self.built_in) + list(self._entry_points())
        return names if self.kind is None else [name for name in names if self._of_kind(self._loaded(name))]

    def _loaded(self, name: str) -> type | None:
        try:
            return self._find(name)
        except Exception:  # an entry point's import may fail in any way: it is not listed
            return None

    def get(self, name: str) -> type:
        """The class registered as ``name``; :class:`ValueError` ``'<name>': unknown; <plural>: <names>``."""
        cls = self._find(name)
        if not self._of_kind(cls):
            raise ValueError(f"{name!r}: unknown; {self.plural}: {', '.join(self.names())}")
        return cls

    def options(self, name: str, values: Mapping[str, Any]) -> Any:
        """``values`` as plug-in ``name``'s own ``Options`` model validates them; :class:`ValueError` naming the
        option and the plug-in."""
        try:
            return self.get(name).Options.model_validate(dict(values))
        except ValidationError as exc:
            raise ValueError(f"{describe_validation(exc)} (the {name} options)") from None

    def emulated(self, name: str) -> type | None:
        """The emulated counterpart of plug-in ``name`` (its ``emulated`` "module:Class"), or None: it has none."""
        spec = getattr(self.get(name), "emulated", "")
        return load(spec) if spec else None

    def name_check(self) -> AfterValidator:
        """The config's validator of a plug-in name field: the name, if registered (the error as :meth:`get`). A
        registered name of a kind without ``kind`` is not loaded: a config names its controller without importing
        its driver."""
        def check(name: str | None) -> str | None:
            if name is not None and not (self.kind is None and (name in self.built_in or name in self._entry_points())):
                self.get(name)
            return name

        return AfterValidator(check)

    def options_check(self, name_field: str, fill: bool = True) -> AfterValidator:
        """The config's validator of an options field, checked by the model of the plug-in that ``name_field``
        (a field before it) names: the options with their defaults filled in (``fill``) or as given (then no options
        are taken as the defaults, without loading the plug-in)."""
        def check(values: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
            name = info.data.get(name_field)  # None: no plug-in, or its name failed its own check
            if name is None or not (fill or values):
                return values
            options = self.options(name, values)
            return options.model_dump() if fill else values

        return AfterValidator(check)


IMU_CODECS = Registry("IMU protocols", CODEC_GROUPS, CODECS_BUILT_IN, kind=Stream.IMU)
TABLE_CODECS = Registry("table data protocols", CODEC_GROUPS, CODECS_BUILT_IN, kind=Stream.TABLE)
CODECS = Registry("protocols", CODEC_GROUPS, CODECS_BUILT_IN)  # every codec, for hil decode
TABLE_CONTROLLERS = Registry("table controllers", ("turntable_hil.table_controllers",), {
    "acutrol": "drivers.acutrol_controller:AcutrolController",
    "aerosmith": "drivers.aerosmith_controller:AerosmithController"})
CHAMBERS = Registry("chamber controllers", ("turntable_hil.chambers",), {"watlow-f4": "drivers.watlow_f4:WatlowF4"})
POWER_SUPPLIES = Registry("power supplies", ("turntable_hil.power_supplies",),
                          {"scpi": "drivers.scpi_supply:ScpiSupply"})


def make_codec(name: str, **options: Any) -> Any:
    """A codec instance, e.g. ``make_codec("kvh1750", rate_hz=1000, gyro_output="rate")`` or
    ``make_codec("tts1", pulses_per_frame=2)``."""
    return CODECS.get(name)(**options)


def imu_codec(imu: Any, rate_hz: float) -> Any:
    """The IMU codec an ``imu`` config block asks for."""
    return IMU_CODECS.get(imu.protocol).from_config(imu, rate_hz)
