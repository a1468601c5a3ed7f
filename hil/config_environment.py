"""The config's ``environment`` block (docs/contracts.md, "environment"): the bench power supply that feeds the
unit, a real one over SCPI or the emulated one. The chamber is not controlled yet."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from hil.config_types import Model

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


class EnvironmentConfig(Model):
    power: PowerConfig | None = None
