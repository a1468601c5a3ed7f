"""A bench power supply over SCPI (pyvisa, with the pure-Python pyvisa-py backend): the command set Keysight's
E36xx and Rohde & Schwarz's HMP supplies share: ``*IDN?``; ``INST:NSEL n`` selecting the output a multi-output
supply then takes its commands for; ``VOLT v`` and ``CURR i`` (set point and current limit); ``OUTP ON|OFF``;
``MEAS:VOLT?`` and ``MEAS:CURR?``. Every setting written is read back (``VOLT?``, ``CURR?``, ``OUTP?``,
``INST:NSEL?``) and a supply that does not confirm it is a :class:`SupplyError` naming the command."""

from __future__ import annotations

import math
from dataclasses import dataclass

READBACK_TOLERANCE = 1e-3  # relative: a set point read back further than this from the one written is refused
TIMEOUT_MS = 2000


class SupplyError(RuntimeError):
    """The supply cannot be reached, or did not confirm a setting; the message names the resource and command."""


@dataclass(frozen=True)
class SupplySettings:
    """What the harness sets on the supply: the output's voltage (V), its current limit (A) and, on a supply
    with several outputs, the output's number (None: the supply's only or selected one)."""

    voltage_v: float
    current_limit_a: float
    channel: int | None = None


@dataclass(frozen=True)
class Reading:
    """The output's state as the supply reports it: on or off, the measured voltage (V) and current (A)."""

    output_on: bool
    voltage_v: float
    current_a: float


class ScpiSupply:
    """One supply at the VISA resource ``resource`` (``TCPIP::HOST::PORT::SOCKET``, ``ASRL/dev/ttyUSB0::INSTR``,
    ``TCPIP::HOST::INSTR``), open between :meth:`open` and :meth:`close`."""

    def __init__(self, resource: str, settings: SupplySettings) -> None:
        self.resource, self.settings = resource, settings
        self.identity = ""
        self._instrument = None

    def open(self) -> ScpiSupply:
        """Connect, identify the supply, select its output and write the voltage and current limit (read back)."""
        import pyvisa

        try:
            manager = pyvisa.ResourceManager("@py")
            self._instrument = manager.open_resource(self.resource, read_termination="\n", write_termination="\n",
                                                     timeout=TIMEOUT_MS)
            self.identity = self.query("*IDN?")
        except (pyvisa.Error, OSError, ValueError) as exc:
            raise SupplyError(f"power supply {self.resource}: cannot connect: {exc}") from None
        if self.settings.channel is not None:
            self._set("INST:NSEL", str(self.settings.channel), lambda text: int(float(text)) == self.settings.channel)
        self._set("VOLT", f"{self.settings.voltage_v:g}", lambda text: _close(text, self.settings.voltage_v))
        self._set("CURR", f"{self.settings.current_limit_a:g}",
                  lambda text: _close(text, self.settings.current_limit_a))
        return self

    def close(self) -> None:
        if self._instrument is not None:
            self._instrument.close()
            self._instrument = None

    def query(self, command: str) -> str:
        try:
            return self._instrument.query(command).strip()
        except Exception as exc:  # pyvisa's errors, a timeout, a dropped socket: one message naming the command
            raise SupplyError(f"power supply {self.resource}: {command}: {exc}") from None

    def output(self, on: bool) -> None:
        """Switch the output on or off, read back with ``OUTP?``."""
        self._set("OUTP", "ON" if on else "OFF", lambda text: _state(text) == on)

    def read(self) -> Reading:
        """The output's state, measured voltage and current."""
        replies = [self.query(command) for command in ("OUTP?", "MEAS:VOLT?", "MEAS:CURR?")]
        try:
            return Reading(_state(replies[0]), _number(replies[1]), _number(replies[2]))
        except ValueError as exc:
            raise SupplyError(f"power supply {self.resource}: {exc}") from None

    def _set(self, command: str, value: str, confirmed) -> None:
        """Write ``command value``, then ask ``command?``: a reply ``confirmed`` refuses is a :class:`SupplyError`."""
        try:
            self._instrument.write(f"{command} {value}")
        except Exception as exc:
            raise SupplyError(f"power supply {self.resource}: {command} {value}: {exc}") from None
        reply = self.query(f"{command}?")
        try:
            ok = confirmed(reply)
        except ValueError:
            ok = False
        if not ok:
            raise SupplyError(f"power supply {self.resource}: {command} {value}: read back {reply!r}")


def _number(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"not a finite number: {text!r}")
    return value


def _close(text: str, expected: float) -> bool:
    return abs(_number(text) - expected) <= READBACK_TOLERANCE * max(abs(expected), 1e-3)


def _state(text: str) -> bool:
    """``OUTP?``'s reply as on (``1``/``ON``) or off (``0``/``OFF``)."""
    words = {"1": True, "ON": True, "0": False, "OFF": False}
    if text.upper() not in words:
        raise ValueError(f"output state {text!r}")
    return words[text.upper()]
