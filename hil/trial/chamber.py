"""The thermal chamber of a live trial (``environment.chamber``): opened before the table moves, at its
``set_point_c``; on every way out, after the table is off, sent to ``on_exit`` and closed."""

from __future__ import annotations

import sys

from drivers.registry import CHAMBERS
from hil.config_environment import ChamberConfig
from hil.trial.outcome import TrialSetupError


def open_chamber(cfg: ChamberConfig | None, ports: dict | None):
    """The chamber's controller, open and at ``set_point_c`` (None without a chamber); a chamber that does not
    answer is a :class:`TrialSetupError` naming ``environment.chamber`` and the port."""
    from drivers.watlow_f4 import ChamberError

    if cfg is None:
        return None
    if cfg.source == "emulator":
        if not ports or "chamber" not in ports:
            raise TrialSetupError("environment.chamber: source: emulator, but the emulator opened no chamber port")
        port, cls, options = ports["chamber"], CHAMBERS.get("watlow-f4"), {}
    else:
        port, cls, options = cfg.port, CHAMBERS.get(cfg.controller), cfg.options
    controller = cls(port, cls.Options.model_validate(options))
    try:
        controller.open()
        if cfg.set_point_c is not None:
            controller.set_set_point_c(cfg.set_point_c)
    except ChamberError as exc:
        controller.close()
        raise TrialSetupError(f"environment.chamber: {exc}") from None
    return controller


def release_chamber(controller, cfg: ChamberConfig) -> None:
    """Send the chamber to ``on_exit`` (``hold``: leave its set point) and close it; a failure is a warning."""
    from drivers.watlow_f4 import ChamberError

    try:
        if cfg.on_exit != "hold":
            controller.set_set_point_c(cfg.on_exit)
    except ChamberError as exc:
        print(f"hil: WARNING: could not set the chamber to its on_exit set point: {exc}", file=sys.stderr)
    finally:
        controller.close()
