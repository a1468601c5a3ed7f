"""An IMU's CAN bus and which DBC signals carry what: the config's ``imu.can`` block (docs/contracts.md), read by
the CAN codec and the capture decoder."""

from __future__ import annotations

from pydantic import Field

from hil.config_types import Model


class CanSignals(Model):
    """Which DBC signals carry which quantity, as ``Message.Signal`` (x, y, z order).

    Each signal's DBC unit says what it is: an increment (rad, deg, m/s) or a rate (rad/s, deg/s,
    m/s^2, g), which the driver converts to increments with the IMU rate.
    """

    gyro: tuple[str, str, str] = ("IMU_DThetaX.DThetaX", "IMU_DThetaY.DThetaY", "IMU_DThetaZ.DThetaZ")
    accel: tuple[str, str, str] = ("IMU_DVX.DVX", "IMU_DVY.DVY", "IMU_DVZ.DVZ")
    sync: str | None = "SyncCounter"  # signal name present in every message above; None: count samples
    status: str | None = "Status"  # fault flags present in every message above (OR-ed), or None
    temperature: str | None = None  # the IMU's temperature (deg C) as Message.Signal, or None


class CanConfig(Model):
    """The IMU's python-can bus. The default, ``udp_multicast`` on python-can's IPv4 group (hop limit 0:
    never off this host), can be opened by another process; ``virtual`` only within one process."""

    interface: str = "udp_multicast"
    channel: str = "239.74.163.2"
    dbc: str = "configs/imu_lab_highres.dbc"
    bitrate: int = Field(1_000_000, gt=0)
    signals: CanSignals = CanSignals()

    @property
    def port(self) -> dict[str, str | int]:
        """The bus as :func:`drivers.transport.open_transport` takes it."""
        return {"interface": self.interface, "channel": self.channel, "bitrate": self.bitrate}
