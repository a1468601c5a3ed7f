"""The emulated thermal chamber: a Watlow Series F4's Modbus RTU registers (:mod:`drivers.watlow_f4`) on a
pseudo-terminal, over a first-order chamber whose air follows set point 1 with time constant ``tau_s`` and no
faster than ``ramp_c_per_min_max``. Function 03 (read holding registers) and 06 (write single register) are
answered as the F4 does; a request for another address or with a bad CRC gets no reply, another function
exception 01, an unknown register exception 02, a value out of range exception 03."""

from __future__ import annotations

import math
import os
import select
import threading
import tty
from collections.abc import Callable

from drivers.crc import crc16_modbus
from drivers.watlow_f4 import DECIMALS, DEG_C, PROCESS_VALUE, SET_POINT_1, UNITS, c_to_unit, to_signed, unit_to_c
from hil.config_environment import ChamberConfig

READ, WRITE = 0x03, 0x06
ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE = 0x01, 0x02, 0x03
POLL_MS = 100


class ChamberModel:
    """The chamber's air temperature (deg C) at trial time t: d T/dt = (set point - T) / tau_s, its magnitude at
    most ``ramp_c_per_min_max`` / 60; starts at ``start_c``. From ``fault_at_s`` (a heater fault) the air holds the
    temperature it has then, whatever the set point."""

    def __init__(self, tau_s: float, ramp_c_per_min_max: float, start_c: float,
                 fault_at_s: float | None = None) -> None:
        self.tau_s, self.ramp = tau_s, ramp_c_per_min_max / 60.0
        self.temperature_c = self.set_point_c = start_c
        self.t = 0.0
        self.fault_at_s = fault_at_s

    def advance(self, t: float) -> float:
        """The temperature at trial time ``t`` (>= the last), the set point held since the last call."""
        if self.fault_at_s is not None and t > self.fault_at_s:
            if self.t < self.fault_at_s:
                self._follow(self.fault_at_s)
            self.t = max(t, self.t)
            return self.temperature_c
        return self._follow(t)

    def _follow(self, t: float) -> float:
        """The air moved on to trial time ``t`` (>= the last) towards the set point."""
        dt, self.t = max(t - self.t, 0.0), max(t, self.t)
        gap = self.set_point_c - self.temperature_c
        if abs(gap) / self.tau_s > self.ramp:  # ramp-limited until the gap is ramp * tau, then exponential
            ramp_s = (abs(gap) - self.ramp * self.tau_s) / self.ramp
            if dt <= ramp_s:
                self.temperature_c += math.copysign(self.ramp * dt, gap)
                return self.temperature_c
            self.temperature_c = self.set_point_c - math.copysign(self.ramp * self.tau_s, gap)
            dt -= ramp_s
        self.temperature_c = self.set_point_c - (self.set_point_c - self.temperature_c) * math.exp(-dt / self.tau_s)
        return self.temperature_c


class F4Registers:
    """The F4's registers over a :class:`ChamberModel`, read at the trial time ``clock()``."""

    def __init__(self, model: ChamberModel, clock: Callable[[], float], address: int = 1, decimals: int = 1) -> None:
        self.model, self.clock, self.address = model, clock, address
        self.settings = {DECIMALS: decimals, UNITS: DEG_C}
        self.lock = threading.Lock()

    def read(self, register: int) -> int:
        """A register's 16 bits; KeyError for one the emulation does not have."""
        if register in self.settings:
            return self.settings[register]
        value_c = {PROCESS_VALUE: lambda: self.model.advance(self.clock()),
                   SET_POINT_1: lambda: self.model.set_point_c}[register]()
        return round(c_to_unit(value_c, self.settings[UNITS]) * 10 ** self.settings[DECIMALS]) & 0xFFFF

    def write(self, register: int, value: int) -> None:
        """Write a register; KeyError for a read-only or unknown one, ValueError for a value out of range."""
        if register == SET_POINT_1:
            self.model.advance(self.clock())
            self.model.set_point_c = unit_to_c(to_signed(value) / 10 ** self.settings[DECIMALS],
                                               self.settings[UNITS])
        elif register in self.settings:
            if value not in ((0, 1, 2, 3) if register == DECIMALS else (0, 1)):
                raise ValueError(value)
            self.settings[register] = value
        else:
            raise KeyError(register)

    def reply(self, request: bytes) -> bytes | None:
        """The response frame to one 8-byte request frame (None: not for this address, or a bad CRC)."""
        if request[0] != self.address or crc16_modbus(request[:6]) != int.from_bytes(request[6:8], "little"):
            return None
        function, register, value = request[1], int.from_bytes(request[2:4], "big"), int.from_bytes(request[4:6], "big")
        with self.lock:
            try:
                if function == READ:
                    words = [self.read(register + k) for k in range(value)]
                    pdu = bytes([READ, 2 * len(words)]) + b"".join(w.to_bytes(2, "big") for w in words)
                elif function == WRITE:
                    self.write(register, value)
                    pdu = request[1:6]
                else:
                    pdu = bytes([function | 0x80, ILLEGAL_FUNCTION])
            except KeyError:
                pdu = bytes([function | 0x80, ILLEGAL_ADDRESS])
            except ValueError:
                pdu = bytes([function | 0x80, ILLEGAL_VALUE])
        frame = bytes([self.address]) + pdu
        return frame + crc16_modbus(frame).to_bytes(2, "little")


class EmulatedChamber:
    """:class:`F4Registers` served on a pseudo-terminal (:attr:`path`) by a thread, until :meth:`close`."""

    def __init__(self, registers: F4Registers) -> None:
        self.registers = registers
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)  # bytes pass unchanged; the slave stays open so the master never sees a hang-up
        self.path = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="chamber", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        buffer = b""
        poller = select.poll()
        poller.register(self.master, select.POLLIN)
        while not self._stop.is_set():
            if not poller.poll(POLL_MS):
                buffer = b""  # a silence ends a frame, as an RTU line's 3.5 characters do
                continue
            buffer += os.read(self.master, 256)
            while len(buffer) >= 8:
                reply = self.registers.reply(buffer[:8])
                if reply is None and buffer[0] == self.registers.address:
                    buffer = buffer[1:]  # a bad CRC: look for the next frame one byte on
                    continue
                buffer = buffer[8:]
                if reply is not None:
                    os.write(self.master, reply)

    def __deepcopy__(self, memo: dict) -> EmulatedChamber:
        """One chamber: a copied sensor state (emulators.sources re-computes a chunk from one) still reads it."""
        return self

    def air_at(self, t: float) -> float:
        """The air's temperature (deg C) at trial time ``t`` (no earlier than the last), the model moved there."""
        with self.registers.lock:
            return self.registers.model.advance(t)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        os.close(self.master)
        os.close(self._slave)


def emulated_chamber(cfg: ChamberConfig) -> EmulatedChamber:
    """The emulated chamber of ``environment.chamber`` (``source: emulator``) at address 1, its air starting at
    ``set_point_c`` (else ``ambient_c``); its time is the emulated IMU's, moved on by :meth:`EmulatedChamber.air_at`."""
    model = chamber_model(cfg)
    return EmulatedChamber(F4Registers(model, lambda: model.t))


def chamber_model(cfg: ChamberConfig) -> ChamberModel:
    """The first-order chamber of ``environment.chamber``, its air starting at ``set_point_c`` (else ``ambient_c``)."""
    start = cfg.ambient_c if cfg.set_point_c is None else cfg.set_point_c
    return ChamberModel(cfg.tau_s, cfg.ramp_c_per_min_max, start, cfg.heater_fault_at_s)


class SimulatedChamber:
    """A chamber controller's interface (``temperature_c``, ``set_point_c``, ``set_set_point_c``) straight over a
    :class:`ChamberModel` in this process, for a simulated trial (``--simulate``): its reading at the model's time,
    which the simulated IMU's samples move on, to the F4's one decimal."""

    def __init__(self, model: ChamberModel) -> None:
        self.model = model

    def temperature_c(self) -> float:
        return round(self.model.temperature_c, 1)

    def set_point_c(self) -> float:
        return self.model.set_point_c

    def set_set_point_c(self, value_c: float) -> None:
        self.model.set_point_c = round(value_c, 1)

    def close(self) -> None:
        """Nothing to release."""
