"""The rig (hil/trial/rig.py) is the one module of the harness that builds a transport or opens a device: no other
module of hil/ calls what makes a port, a bus, an instrument, a table's control, a chamber's or a supply's driver, or
an emulated device."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RIG = ROOT / "hil" / "trial" / "rig.py"
# what makes a transport or a device: the drivers' openers and transports, the libraries' own, the table's control,
# the registries' chamber and supply drivers, and the emulated devices the harness starts
OPENERS = {"open_transport", "open_serial", "serial_for_url", "SerialTransport", "CanTransport", "Bus",
           "ResourceManager", "ModbusSerialClient", "ModbusTcpClient", "TableControl", "spawn_emulator",
           "EmulatedSupply", "emulated_chamber"}
REGISTRIES = {"CHAMBERS", "POWER_SUPPLIES"}


def device_calls(source: str) -> list[tuple[int, str]]:
    """(line, name) of every call in ``source`` that builds a transport or opens a device."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
        owner = func.value.id if isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) else ""
        if name in OPENERS or owner in REGISTRIES and name == "get":  # a registry's checks open nothing
            found.append((node.lineno, f"{owner}.{name}" if owner else name))
    return found


def test_no_module_outside_the_rig_builds_a_transport_or_opens_a_device():
    found = [f"{path.relative_to(ROOT)}:{line}: {name}" for path in sorted((ROOT / "hil").rglob("*.py"))
             if path != RIG for line, name in device_calls(path.read_text())]
    assert not found, "\n".join(found)


def test_the_rig_check_finds_every_way_of_opening():
    source = ("t = open_transport(url, 'imu')\nbus = can.Bus(interface='virtual')\nrm = pyvisa.ResourceManager()\n"
              "c = CHAMBERS.get('watlow-f4')\ncontrol = TableControl(url, table)\nopen_serial(url, 'x')\n"
              "reader = DeviceReader(transport)\nsettings = SupplySettings(1, 2, None)\nCHAMBERS.name_check()\n")
    assert device_calls(source) == [(1, "open_transport"), (2, "can.Bus"), (3, "pyvisa.ResourceManager"),
                                    (4, "CHAMBERS.get"), (5, "TableControl"), (6, "open_serial")]


def test_the_rig_itself_opens_every_kind_of_device():
    names = {name.rpartition(".")[2] for _, name in device_calls(RIG.read_text())}
    assert {"open_transport", "TableControl", "spawn_emulator", "EmulatedSupply", "get"} <= names
