"""Xbus messages besides MTData2 (MT Low Level Communication Protocol; ethz-asl/ethzasl_xsens_driver mtdef.py): any
message found in a byte stream, the names of the data identifiers, and the MTi's configuration check
(docs/devices.md, "Configuration check")."""

from __future__ import annotations

import struct

from drivers.config_query import ConfigDialogue, DeviceConfig, Exchange, Setting, UnreadableReply

MAX_PAYLOAD = 2048  # longer announced lengths are taken as a false sync

# Names of the data types (bits 0-3 cleared), for the counts by kind of the items not read and the output
# configuration.
TYPE_NAMES: dict[int, str] = {
    0x8030: "DeltaQ", 0x4010: "DeltaV", 0x4020: "Acceleration", 0x8020: "RateOfTurn",
    0x0810: "Temperature", 0x1010: "UtcTime", 0x1020: "PacketCounter", 0x1060: "SampleTimeFine",
    0x1070: "SampleTimeCoarse", 0x2010: "Quaternion",
    0x2020: "RotationMatrix", 0x2030: "EulerAngles", 0x3010: "BaroPressure", 0x4030: "FreeAcceleration",
    0x5020: "AltitudeEllipsoid", 0x5030: "PositionEcef", 0x5040: "LatLon", 0x7010: "GnssPvtData",
    0x7020: "GnssSatInfo", 0xA010: "AccelerationHR", 0xB010: "RateOfTurnHR", 0xC020: "MagneticField",
    0xD010: "VelocityXYZ", 0xE010: "StatusByte", 0xE020: "StatusWord",
}


def item_kind(xdi: int) -> str:
    """How an item is named (the counts of :meth:`drivers.xsens.XsensCodec.count_items`, an output
    configuration): its type's name, or its identifier."""
    return f"{TYPE_NAMES.get(xdi & 0xFFF0, 'item')} 0x{xdi:04X}"


# A message is ``FA FF MID LEN data CS``, the bytes after the preamble summing to 0 mod 256; a request's
# acknowledgement is MID + 1. GoToConfig stops the MTData2 stream, ReqOutputConfiguration (0xC0, no data) is
# answered 0xC1 with (DataID, output frequency) uint16 pairs (0xFFFF: with every message), GoToMeasurement resumes.
GO_TO_CONFIG, GO_TO_MEASUREMENT, REQ_OUTPUT_CONFIGURATION, ERROR = 0x30, 0x10, 0xC0, 0x42
EVERY_MESSAGE = 0xFFFF  # the output frequency of an item sent with every message (counters, status)
# The motion items ``imu.options.outputs`` names (identifiers with the precision bits clear)
OUTPUT_ITEMS: dict[str, tuple[int, int]] = {"increments": (0x8030, 0x4010), "rates": (0x8020, 0x4020)}


def xbus_message(mid: int, data: bytes = b"") -> bytes:
    """An Xbus message to or from the master (bus identifier 0xFF), with its checksum."""
    size = bytes([len(data)]) if len(data) < 0xFF else b"\xff" + len(data).to_bytes(2, "big")
    body = bytes([0xFF, mid]) + size + data
    return b"\xfa" + body + bytes([-sum(body) & 0xFF])


def xbus_messages(buf: bytes | bytearray) -> tuple[list[tuple[int, bytes]], int]:
    """The whole, valid Xbus messages in ``buf`` as (MID, data), whatever lies between them skipped, and how many
    bytes of ``buf`` are done with (up to a message that may still be arriving)."""
    found: list[tuple[int, bytes]] = []
    pos = done = 0
    waiting: int | None = None  # the first candidate after the last message found that is not whole yet
    while (pos := buf.find(b"\xfa\xff", pos)) >= 0:
        end = _message_end(buf, pos)
        if end is None:
            waiting = pos if waiting is None else waiting
        elif end and sum(buf[pos + 1:end]) & 0xFF == 0:
            found.append((buf[pos + 2], bytes(buf[pos + (6 if buf[pos + 3] == 0xFF else 4):end - 1])))
            pos = done = end
            waiting = None
            continue
        pos += 1
    rest = waiting if waiting is not None else len(buf) - buf.endswith(b"\xfa")
    return found, max(done, rest)


def _message_end(buf: bytes | bytearray, pos: int) -> int | None:
    """Where the message starting at ``pos`` ends; None while its length is not all there, 0 if it is too long."""
    if pos + 4 > len(buf) or buf[pos + 3] == 0xFF and pos + 6 > len(buf):
        return None
    header, size = (4, buf[pos + 3]) if buf[pos + 3] < 0xFF else (6, int.from_bytes(buf[pos + 4:pos + 6], "big"))
    end = pos + header + size + 1
    return 0 if size > MAX_PAYLOAD else end if end <= len(buf) else None


def output_configuration(data: bytes) -> list[tuple[int, int]]:
    """The (DataID, output frequency) pairs of an OutputConfiguration message's data."""
    if len(data) % 4:
        raise UnreadableReply(f"the MTi's OutputConfiguration holds {len(data)} bytes, not (DataID, frequency) pairs: "
                              f"{data.hex(' ').upper()}")
    return [struct.unpack_from(">HH", data, k) for k in range(0, len(data), 4)]


def describe_outputs(pairs: list[tuple[int, int]]) -> str:
    """An output configuration as a lab reads it: each item's name, identifier and frequency."""
    return ", ".join(f"{item_kind(xdi)} {'with every message' if hz == EVERY_MESSAGE else f'at {hz} Hz'}"
                     for xdi, hz in pairs)


def stated_outputs(pairs: list[tuple[int, int]], reply: str) -> tuple[Setting, ...]:
    """The config keys an output configuration sets: ``imu.options.outputs`` (the motion items the codec reads,
    in the default coordinates: "increments", "rates" or "neither") and ``imu.rate_hz`` (their frequency, unless
    sent with every message)."""
    rates = {xdi & 0xFFF0: hz for xdi, hz in pairs if not xdi & 0xC}
    outputs = next((name for name, items in OUTPUT_ITEMS.items() if all(x in rates for x in items)), "neither")
    settings = [Setting("imu.options.outputs", outputs, reply)]
    stated = {rates[x] for x in OUTPUT_ITEMS.get(outputs, ())} - {EVERY_MESSAGE}
    if stated:
        settings.insert(0, Setting("imu.rate_hz", float(min(stated)), reply))
    return tuple(settings)


class XsensConfigDialogue(ConfigDialogue):
    """GoToConfig, ReqOutputConfiguration, then GoToMeasurement whatever happened."""

    def query(self, port: Exchange) -> DeviceConfig:
        try:
            self._ask(port, GO_TO_CONFIG, "GoToConfig")
            data = self._ask(port, REQ_OUTPUT_CONFIGURATION, "ReqOutputConfiguration")
            reply = describe_outputs(pairs := output_configuration(data))
            self._ask(port, GO_TO_MEASUREMENT, "GoToMeasurement")
        except BaseException:
            port.send(xbus_message(GO_TO_MEASUREMENT))
            raise
        return DeviceConfig({"GoToConfig": "GoToConfigAck", "ReqOutputConfiguration": reply,
                             "GoToMeasurement": "GoToMeasurementAck"}, stated_outputs(pairs, reply))

    @staticmethod
    def _ask(port: Exchange, mid: int, name: str) -> bytes:
        """The data of the device's acknowledgement of request ``mid``; an Error message is unreadable."""
        def answer(buf: bytearray) -> bytes | None:
            for got, data in xbus_messages(buf)[0]:
                if got == ERROR:
                    raise UnreadableReply(f"the MTi answers {name} (0x{mid:02X}) with Error "
                                          f"{xbus_message(ERROR, data).hex(' ').upper()}")
                if got == mid + 1:
                    return data
            return None
        return port.ask(xbus_message(mid), answer, f"{name} (0x{mid:02X})")
