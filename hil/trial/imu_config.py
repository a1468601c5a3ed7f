"""The IMU's own configuration, asked for on its port as the trial attaches (docs/devices.md, "Configuration
check"): a device set otherwise than the config is refused before anything is acquired, naming the key and what
the device said; a device that does not answer is warned of, and the trial goes on unchecked."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from drivers.codec import Codec
from drivers.config_query import Exchange, NoAnswer, UnreadableReply
from drivers.transport import Transport
from hil.inputs import InputError


class ConfigMismatch(InputError):
    """The IMU says it is set otherwise than the config, or answers what its codec cannot read."""


def check_imu_config(codec: Codec, transport: Transport, warn: Callable[[str], None]) -> dict[str, Any] | None:
    """result.json's ``record.imu_config``: what the IMU on ``transport`` (opened and closed again here, its reader
    opens it anew) says of its configuration; None when it is not asked (a protocol without a query,
    ``imu.options.check_config`` false, a CAN bus). Raises :class:`ConfigMismatch` on a setting that differs from
    the config or a reply the codec cannot read."""
    dialogue = codec.config_dialogue()
    if dialogue is None or not transport.byte_stream:
        return None
    transport.open()
    try:
        device = dialogue.query(Exchange(transport))
    except NoAnswer as exc:
        warn(f"imu: {exc} on {transport.address}: its configuration is not checked (a read-only line? "
             "imu.options.check_config: false skips the query)")
        return {"answered": False, "replies": {}, "settings": {}}
    except UnreadableReply as exc:
        raise ConfigMismatch(f"imu: {exc}; check imu.protocol and the IMU's output settings") from None
    finally:
        transport.close()
    mismatches = device.mismatches(codec.expected_config())
    if mismatches:
        raise ConfigMismatch("; ".join(mismatches) + ": set the config to the IMU's settings (or the IMU to the "
                             "config's)")
    return device.as_record()
