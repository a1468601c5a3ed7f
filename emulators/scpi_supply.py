"""The emulated bench power supply: a SCPI instrument on a TCP socket of 127.0.0.1 (VISA resource
``TCPIP::127.0.0.1::PORT::SOCKET``, one command or query a line), answering the commands of
:mod:`drivers.scpi_supply` as a Keysight E36xx does (``*IDN?``, ``INST:NSEL``, ``VOLT``, ``CURR``, ``OUTP``,
``MEAS:VOLT?``, ``MEAS:CURR?``, ``SYST:ERR?``), any client served. Its output powers the emulated unit: the
unit is powered while its output is on at a voltage above 0, each power-on is counted and told to ``on_power``,
and the unit draws ``load_a`` (within the current limit) while powered. ``hil emulate`` starts it
(:func:`powering`) feeding the emulated IMU's :class:`emulators.clocks.PowerLine`."""

from __future__ import annotations

import socketserver
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from emulators.clocks import PowerLine
    from hil.config_environment import PowerConfig

IDENTITY = "turntable-hil,emulated supply E3631-like,0,1.0"
CHANNELS = 3
NO_ERROR = '+0,"No error"'
UNDEFINED_HEADER = '-113,"Undefined header"'


class SupplyState:
    """The emulated supply's outputs: the selected one, each one's set points and state, the errors queued, and
    how often the unit on its output (``unit_channel``) was powered on; ``on_power(powered)`` is called (with
    :attr:`lock` held) whenever the unit is powered on or off."""

    def __init__(self, load_a: float, unit_channel: int = 1) -> None:
        self.load_a, self.unit_channel = load_a, unit_channel
        self.on_power: Callable[[bool], None] | None = None
        self.selected = 1
        self.voltage = dict.fromkeys(range(1, CHANNELS + 1), 0.0)
        self.current = dict.fromkeys(range(1, CHANNELS + 1), 1.0)
        self.on = dict.fromkeys(range(1, CHANNELS + 1), False)
        self.power_ons = 0
        self.errors: list[str] = []
        self.lock = threading.Lock()

    def handle(self, line: str) -> str | None:
        """The reply to one line (None for a command without one)."""
        header, _, argument = line.strip().partition(" ")
        header = header.upper()
        with self.lock:
            powered = self.powered()
            handler = self._handlers().get(header)
            if handler is None:
                self.errors.append(UNDEFINED_HEADER)
                return None
            try:
                return handler(argument.strip())
            except (ValueError, KeyError):
                self.errors.append('-224,"Illegal parameter value"')
                return None
            finally:
                if self.powered() != powered:
                    self._powered(not powered)

    def powered(self) -> bool:
        """Whether the unit is powered: its output on, at a voltage above 0."""
        return self.on[self.unit_channel] and self.voltage[self.unit_channel] > 0

    def _powered(self, on: bool) -> None:
        self.power_ons += on
        if self.on_power is not None:
            self.on_power(on)

    def _handlers(self) -> dict[str, Callable[[str], str | None]]:
        ch = self.selected
        return {
            "*IDN?": lambda _: IDENTITY, "*RST": lambda _: self._reset(), "*CLS": lambda _: self.errors.clear(),
            "SYST:ERR?": lambda _: self.errors.pop(0) if self.errors else NO_ERROR,
            "INST:NSEL": lambda a: self._select(int(a)), "INST:NSEL?": lambda _: str(ch),
            "VOLT": lambda a: self.voltage.__setitem__(ch, _level(a)), "VOLT?": lambda _: f"{self.voltage[ch]:.6E}",
            "CURR": lambda a: self.current.__setitem__(ch, _level(a)), "CURR?": lambda _: f"{self.current[ch]:.6E}",
            "OUTP": lambda a: self._output(ch, _on(a)), "OUTP?": lambda _: "1" if self.on[ch] else "0",
            "MEAS:VOLT?": lambda _: f"{self.voltage[ch] if self.on[ch] else 0.0:.6E}",
            "MEAS:CURR?": lambda _: f"{self._drawn(ch):.6E}",
        }

    def _reset(self) -> None:
        for ch in self.on:
            self._output(ch, False)

    def _select(self, channel: int) -> None:
        if channel not in self.on:
            raise ValueError(channel)
        self.selected = channel

    def _output(self, channel: int, on: bool) -> None:
        self.on[channel] = on

    def _drawn(self, channel: int) -> float:
        return min(self.load_a, self.current[channel]) if channel == self.unit_channel and self.powered() else 0.0


def _level(text: str) -> float:
    value = float(text)
    if not value >= 0:
        raise ValueError(text)
    return value


def _on(text: str) -> bool:
    return {"ON": True, "1": True, "OFF": False, "0": False}[text.upper()]


class _Session(socketserver.StreamRequestHandler):
    """One client: a line in, the reply (if any) out."""

    def handle(self) -> None:
        for raw in self.rfile:
            reply = self.server.state.handle(raw.decode("ascii", errors="replace"))
            if reply is not None:
                self.wfile.write(reply.encode("ascii") + b"\n")


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True


class EmulatedSupply:
    """The supply's server on 127.0.0.1 (``port`` 0: any free one), serving in a thread until :meth:`close`."""

    def __init__(self, state: SupplyState, port: int = 0) -> None:
        self.state = state
        self._server = _Server(("127.0.0.1", port), _Session)
        self._server.state = state
        self._thread = threading.Thread(target=self._server.serve_forever, name="emulated-supply", daemon=True)
        self._thread.start()

    @property
    def resource(self) -> str:
        """The VISA resource a client opens."""
        return f"TCPIP::127.0.0.1::{self._server.server_address[1]}::SOCKET"

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(5)


def powering(cfg: PowerConfig, lines: Sequence[PowerLine], lock: threading.RLock) -> EmulatedSupply:
    """The emulated supply of ``environment.power`` for ``hil emulate``: the unit's output on at the configured
    voltage and current limit from the start (the IMUs stream as powered hardware does), then each switch of the
    unit's power switching every IMU's ``lines`` with ``lock`` held (the lock the emulator's pulse loop takes)."""

    def switch(on: bool) -> None:
        with lock:
            for line in lines:
                line.switch(on)

    state = SupplyState(cfg.load_a, cfg.options.channel or 1)
    for command in (f"INST:NSEL {state.unit_channel}", f"VOLT {cfg.options.voltage_v:g}",
                    f"CURR {cfg.options.current_limit_a:g}", "OUTP ON"):
        state.handle(command)
    state.on_power = switch
    return EmulatedSupply(state)
