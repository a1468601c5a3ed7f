"""A thermal chamber's Watlow Series F4 controller over Modbus RTU, through pymodbus's serial client.

The registers (Watlow Series F4P User's Manual, chapter 9, "Modbus Registers"): 100 Input 1 Value (the
process value, read only), 300 Set Point 1 (read/write), 606 Input 1 Decimal (0: 0, 1: 0.0, 2: 0.00,
3: 0.000), 901 deg F or deg C (0: deg F, 1: deg C). Values are signed 16-bit integers scaled by the decimal
setting, in the unit register 901 names; the harness works in deg C and converts. The serial line is 8 data
bits, no parity, 1 stop bit, at 9600 or 19200 baud (the controller's Communications menu). Every set point
written is read back, and a controller that does not confirm it is a :class:`ChamberError`."""

from __future__ import annotations

import logging
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

logging.getLogger("pymodbus").addHandler(logging.NullHandler())  # its errors reach the user as ChamberError
PROCESS_VALUE, SET_POINT_1, DECIMALS, UNITS = 100, 300, 606, 901
DEG_F, DEG_C = 0, 1


class ChamberError(RuntimeError):
    """The controller cannot be reached, refused a request or did not confirm a write; names the port."""


class WatlowF4Options(BaseModel):
    """``environment.chamber.options`` of a ``watlow-f4`` controller."""

    model_config = ConfigDict(extra="forbid")
    address: int = Field(1, ge=1, le=247)  # the controller's Modbus address (Communications menu)
    baudrate: Literal[9600, 19200] = 19200  # the F4 offers these two
    timeout_s: float = Field(1.0, gt=0, le=30)


def to_signed(raw: int) -> int:
    """A register's 16 bits as the signed integer the F4 stores."""
    return raw - 0x10000 if raw & 0x8000 else raw


def c_to_unit(value_c: float, units: int) -> float:
    return value_c * 9.0 / 5.0 + 32.0 if units == DEG_F else value_c


def unit_to_c(value: float, units: int) -> float:
    return (value - 32.0) * 5.0 / 9.0 if units == DEG_F else value


class WatlowF4:
    """One F4 at serial ``port``, open between :meth:`open` and :meth:`close`; temperatures in deg C."""

    name = "watlow-f4"
    Options = WatlowF4Options

    def __init__(self, port: str, options: WatlowF4Options | None = None) -> None:
        self.port, self.options = port, options or WatlowF4Options()
        self.decimals, self.units = 0, DEG_C
        self._client = None

    def open(self) -> WatlowF4:
        """Connect and read the decimal setting and the units (a controller that does not answer: ChamberError)."""
        from pymodbus.client import ModbusSerialClient

        self._client = ModbusSerialClient(self.port, baudrate=self.options.baudrate, bytesize=8, parity="N",
                                          stopbits=1, timeout=self.options.timeout_s, retries=0)
        if not self._client.connect():
            raise ChamberError(f"chamber at {self.port}: cannot open the serial port")
        self.decimals = self._read(DECIMALS)
        self.units = self._read(UNITS)
        if self.decimals not in (0, 1, 2, 3) or self.units not in (DEG_F, DEG_C):
            raise ChamberError(f"chamber at {self.port}: decimals {self.decimals}, units {self.units}: "
                               "not a Series F4's settings")
        return self

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def temperature_c(self) -> float:
        """The process value (register 100), deg C."""
        return self._to_c(to_signed(self._read(PROCESS_VALUE)))

    def set_point_c(self) -> float:
        """Set point 1 (register 300), deg C."""
        return self._to_c(to_signed(self._read(SET_POINT_1)))

    def set_set_point_c(self, value_c: float) -> None:
        """Write set point 1, rounded to the controller's decimals, and read it back."""
        raw = round(c_to_unit(value_c, self.units) * 10 ** self.decimals)
        if not -0x8000 <= raw <= 0x7FFF:
            raise ChamberError(f"chamber at {self.port}: set point {value_c:g} deg C is beyond a 16-bit register")
        self._call("write register 300", self._client.write_register, SET_POINT_1, raw & 0xFFFF)
        back = to_signed(self._read(SET_POINT_1))
        if back != raw:
            raise ChamberError(f"chamber at {self.port}: set point 1 written {raw}, read back {back}")

    def _to_c(self, raw: int) -> float:
        return unit_to_c(raw / 10 ** self.decimals, self.units)

    def _read(self, register: int) -> int:
        reply = self._call(f"read register {register}", self._client.read_holding_registers, register, count=1)
        return reply.registers[0]

    def _call(self, what: str, request, *args, **kwargs):
        """One request; no reply, an exception reply or a transport error is a ChamberError naming ``what``."""
        from pymodbus.exceptions import ModbusException

        try:
            reply = request(*args, device_id=self.options.address, **kwargs)
        except (ModbusException, OSError) as exc:
            raise ChamberError(f"chamber at {self.port}: {what}: {exc}") from None
        if reply.isError():
            raise ChamberError(f"chamber at {self.port}: {what}: refused ({reply})")
        return reply
