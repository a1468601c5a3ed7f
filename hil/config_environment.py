"""The config's ``environment`` block (docs/contracts.md, "environment"): the bench power supply that feeds the
unit, a real one over SCPI or the emulated one; the thermal chamber around the table, a controller found by
name in :data:`drivers.registry.CHAMBERS` (built-ins and the entry-point group ``turntable_hil.chambers``) or the
emulated one."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from drivers.registry import CHAMBERS, POWER_SUPPLIES
from hil.config_types import Model, Vec2


class PowerOptions(Model):
    """What the harness sets on the supply's output."""

    voltage_v: float = Field(5.0, gt=0, le=1000)
    current_limit_a: float = Field(1.0, gt=0, le=100)
    channel: int | None = Field(None, ge=1, le=16)  # a multi-output supply's output (INST:NSEL); None: as it is


class PowerConfig(Model):
    """``environment.power``: ``controller: scpi`` with a VISA ``port``, or ``source: emulator`` (a SCPI supply
    on 127.0.0.1 whose output powers the emulated unit, drawing ``load_a``)."""

    source: Literal["emulator"] | None = None
    controller: Annotated[str | None, POWER_SUPPLIES.name_check()] = None  # a power supply's registry name
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


class ChamberConfig(Model):
    """``environment.chamber``: ``controller`` (a registered chamber controller, e.g. ``watlow-f4``) with a serial
    ``port`` and its ``options``, or ``source: emulator`` (an emulated F4 on a pty over a first-order chamber
    with time constant ``tau_s`` and ramp limit ``ramp_c_per_min_max``, starting at ``set_point_c``, else at
    ``ambient_c``)."""

    source: Literal["emulator"] | None = None
    controller: Annotated[str | None, CHAMBERS.name_check()] = None  # a chamber controller's registry name
    port: str | None = None
    options: Annotated[dict[str, Any], CHAMBERS.options_check("controller")] = {}  # its Options model's
    set_point_c: float | None = None  # a trial that does not soak runs at this set point; None: left as it is
    limits_c: Vec2 = (-70.0, 180.0)  # the chamber's range: a set point beyond it is refused
    on_exit: Literal["hold"] | float = "hold"  # on every way out: hold the set point, or go to this one (deg C)
    tau_s: float = Field(600.0, gt=0)  # emulator
    ramp_c_per_min_max: float = Field(3.0, gt=0, le=100)  # emulator
    ambient_c: float = Field(25.0, ge=-100, le=200)  # emulator
    heater_fault_at_s: float | None = Field(None, ge=0)  # emulator: from this trial time the air holds where it is

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


class SoakSettings(Model):
    """``calibration.soak``: at each of ``calibration.temperatures_c`` the chamber is sent to the set point and,
    once its reading is within ``stable_within_c`` of it, the IMU's own reported temperature must stay within
    ``stable_within_c`` of its latest value for ``for_s``; ``timeout_s`` from the set point's write ends the trial
    early. A chamber reading that changes less than a tenth of a degree for ``stalled_s`` while it is more than
    2 deg C from its set point (a heater or cooling fault) ends it at once."""

    stable_within_c: float = Field(0.2, gt=0, le=10)
    for_s: float = Field(600.0, gt=0)
    timeout_s: float = Field(14400.0, gt=0)
    stalled_s: float = Field(600.0, gt=0)


def check_temperatures(temperatures: list[float] | None, order: int, chamber: ChamberConfig | None) -> None:
    """``calibration.temperatures_c`` needs a chamber, set points within its ``limits_c`` and more of them than
    ``calibration.thermal_order``; ValueError naming the key otherwise."""
    if temperatures is None:
        return
    if chamber is None:
        raise ValueError("calibration.temperatures_c: a calibration over temperature needs environment.chamber")
    low, high = chamber.limits_c
    for k, value in enumerate(temperatures):
        if not low <= value <= high:
            raise ValueError(f"calibration.temperatures_c[{k}]: {value:g} deg C is outside environment.chamber."
                             f"limits_c [{low:g}, {high:g}]")
    if len(set(temperatures)) <= order:
        raise ValueError(f"calibration.thermal_order: a polynomial of order {order} needs at least {order + 1} "
                         f"different temperatures in calibration.temperatures_c ({len(set(temperatures))} given)")
