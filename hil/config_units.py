"""The config's ``units`` block (docs/units.md): several IMUs on one table, each with its ``name``, its ``record``,
its ``mounting_deg`` on the inner gimbal and its ``imu`` block, in place of the one-unit ``imu``. Checked here
across the units (names, ports, CAN messages); each unit's one-unit config is the shared blocks with the unit's
own (:meth:`hil.config.Config.unit_configs`), so that every one-unit path runs per unit."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hil.inputs import ConfigError

UNIT_NAME = r"^[a-z0-9_-]+$"  # a unit's name: its output directory OUT/units/<name>/
UNIT_SEED_STREAM = 4  # a unit's trial.seed: SeedSequence([trial.seed, 4, *its name's bytes]) (emulators.clocks: 2, 3)


def check_units(units: Sequence[Any] | None, imu_given: bool) -> None:
    """Raise ValueError naming ``units[i].key`` (both units where two clash) when ``imu`` is given beside
    ``units``, two units share a name, a serial port or a CAN message on one bus."""
    if units is None:
        return
    if imu_given:
        raise ValueError("units: a config gives its IMUs either in units or in imu (one unit), not in both")
    seen: dict[object, tuple[int, str]] = {}
    for k, unit in enumerate(units):
        for key, claim, what in _claims(unit):
            if claim in seen:
                j, other = seen[claim]
                raise ValueError(f"units[{k}].{key}: the {what} is also units[{j}].{other}")
            seen[claim] = (k, key)


def _claims(unit: Any) -> list[tuple[str, object, str]]:
    """What one unit has to itself: its name, its serial port, each CAN message it reads on its bus; each as
    (its key, what is claimed, what it is called)."""
    imu = unit.imu
    claims: list[tuple[str, object, str]] = [("name", ("name", unit.name), f"name {unit.name!r}")]
    if imu.port:
        claims.append(("imu.port", ("port", imu.port), f"port {imu.port}"))
    if imu.can is not None:
        can = imu.can
        messages = {signal.partition(".")[0] for signal in (*can.signals.gyro, *can.signals.accel)}
        claims += [("imu.can", ("can", can.interface, can.channel, can.dbc, message),
                    f"CAN message {message} of {can.dbc} on {can.interface} {can.channel}")
                   for message in sorted(messages)]
    return claims


def unit_seed(seed: int, name: str) -> int:
    """The ``trial.seed`` of the unit ``name``: its IMU's own random streams, apart from every other unit's and
    the same wherever the unit stands in ``units``."""
    return int(np.random.SeedSequence([seed, UNIT_SEED_STREAM, *name.encode()]).generate_state(1)[0])


def unit_update(data: dict, unit: Any) -> dict:
    """The one-unit config's data (a config's ``model_dump``) of ``unit``: the shared blocks, the unit's IMU and
    mounting, its own seed and trial name (``<trial>.<unit>``), the shared record with the unit's own over it, no
    ``units``."""
    data = {key: value for key, value in data.items() if key != "units"}
    record = {**data["record"], **unit.record.model_dump(exclude_none=True)}
    return {**data, "imu": unit.imu.model_dump(), "record": record,
            "trial": {**data["trial"], "name": f"{data['trial']['name']}.{unit.name}",
                      "seed": unit_seed(data["trial"]["seed"], unit.name)},
            "turntable": {**data["turntable"], "mounting_deg": list(unit.mounting_deg)}}


def one_unit_only(cfg: Any, source: str) -> Any:
    """``cfg``, a one-unit config; ConfigError for a ``units`` config given where one IMU (``imu``) is taken."""
    if cfg.units:
        raise ConfigError(f"{source}: units: this command takes a one-unit config (imu); hil run, replay, "
                          "simulate, calibrate, noise, emulate and campaign take several units (docs/units.md)")
    return cfg
