"""The config's ``environment`` block (docs/contracts.md, "environment"): the bench power supply that feeds the
unit, a real one over SCPI or the emulated one; the thermal chamber around the table, a controller found by
name (built-ins and the entry-point group ``turntable_hil.chambers``) or the emulated one."""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Any, Literal

from pydantic import Field, ValidationError, ValidationInfo, field_validator, model_validator

from hil.config_types import Model, Vec2, describe_validation

POWER_CONTROLLERS = ("scpi",)


class PowerOptions(Model):
    """What the harness sets on the supply's output."""

    voltage_v: float = Field(5.0, gt=0, le=1000)
    current_limit_a: float = Field(1.0, gt=0, le=100)
    channel: int | None = Field(None, ge=1, le=16)  # a multi-output supply's output (INST:NSEL); None: as it is


class PowerConfig(Model):
    """``environment.power``: ``controller: scpi`` with a VISA ``port``, or ``source: emulator`` (a SCPI supply
    on 127.0.0.1 whose output powers the emulated unit, drawing ``load_a``)."""

    source: Literal["emulator"] | None = None
    controller: Literal[POWER_CONTROLLERS] | None = None
    port: str | None = None  # VISA resource: TCPIP::HOST::PORT::SOCKET, ASRL/dev/ttyUSB0::INSTR, ...
    options: PowerOptions = PowerOptions()
    on_exit: Literal["off", "on"] = "off"
    load_a: float = Field(0.35, ge=0)  # emulator: the unit's current draw while powered
    min_current_a: float = Field(0.01, ge=0)  # a unit drawing less after power-on is an early end

    @field_validator("on_exit", mode="before")
    @classmethod
    def _yaml_on_off(cls, value: object) -> object:
        """YAML 1.1 reads a bare on/off as true/false."""
        return {True: "on", False: "off"}.get(value, value) if isinstance(value, bool) else value

    @model_validator(mode="after")
    def _one_kind(self) -> PowerConfig:
        if (self.source is None) == (self.controller is None):
            raise ValueError("environment.power: expected either source: emulator or controller: scpi with a port")
        if self.controller is not None and not self.port:
            raise ValueError("environment.power.port: a VISA resource such as TCPIP::HOST::PORT::SOCKET is needed")
        return self


CHAMBER_CONTROLLERS = {"watlow-f4": "drivers.watlow_f4:WatlowF4"}  # name -> "module:class"; plug-ins add more
CHAMBER_GROUP = "turntable_hil.chambers"


def chamber_class(name: str) -> type:
    """The chamber controller class registered as ``name`` (built-in or entry point in ``turntable_hil.chambers``);
    ValueError naming the known ones."""
    if name in CHAMBER_CONTROLLERS:
        module, cls = CHAMBER_CONTROLLERS[name].split(":")
        return getattr(importlib.import_module(module), cls)
    found = {ep.name: ep for ep in entry_points(group=CHAMBER_GROUP)}
    if name not in found:
        raise ValueError(f"{name!r}: unknown; chamber controllers: {', '.join([*CHAMBER_CONTROLLERS, *found])}")
    return found[name].load()


class ChamberConfig(Model):
    """``environment.chamber``: ``controller`` (a registered chamber controller, e.g. ``watlow-f4``) with a serial
    ``port`` and its ``options``, or ``source: emulator`` (an emulated F4 on a pty over a first-order chamber
    with time constant ``tau_s`` and ramp limit ``ramp_c_per_min_max``, starting at ``set_point_c``, else at
    ``ambient_c``)."""

    source: Literal["emulator"] | None = None
    controller: str | None = None
    port: str | None = None
    options: dict[str, Any] = {}
    set_point_c: float | None = None  # a trial that does not soak runs at this set point; None: left as it is
    limits_c: Vec2 = (-70.0, 180.0)  # the chamber's range: a set point beyond it is refused
    on_exit: Literal["hold"] | float = "hold"  # on every way out: hold the set point, or go to this one (deg C)
    tau_s: float = Field(600.0, gt=0)  # emulator
    ramp_c_per_min_max: float = Field(3.0, gt=0, le=100)  # emulator
    ambient_c: float = Field(25.0, ge=-100, le=200)  # emulator

    @field_validator("controller")
    @classmethod
    def _known_controller(cls, value: str | None) -> str | None:
        if value is not None:
            chamber_class(value)
        return value

    @field_validator("options")
    @classmethod
    def _controller_options(cls, value: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        """The options as the controller's own Options model validates them, its defaults filled in."""
        if not info.data.get("controller"):
            return value
        try:
            return chamber_class(info.data["controller"]).Options.model_validate(value).model_dump()
        except ValidationError as exc:
            raise ValueError(f"{describe_validation(exc)} (the {info.data['controller']} options)") from None

    @model_validator(mode="after")
    def _one_kind_within_limits(self) -> ChamberConfig:
        if (self.source is None) == (self.controller is None):
            raise ValueError("expected either source: emulator or a controller with a port")
        if self.controller is not None:
            if not self.port:
                raise ValueError("port: the controller's serial port is needed")
        low, high = self.limits_c
        for key in ("set_point_c", "on_exit"):
            value = getattr(self, key)
            if isinstance(value, float) and not low <= value <= high:
                raise ValueError(f"{key}: {value:g} deg C is outside limits_c [{low:g}, {high:g}]")
        return self


class EnvironmentConfig(Model):
    power: PowerConfig | None = None
    chamber: ChamberConfig | None = None
