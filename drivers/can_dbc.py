"""IMU over CAN: frames described by a DBC and decoded with cantools; which signal is which is config.

A sample is the set of configured messages that share one sync counter (or, without a counter, one
of each message in turn). A set left incomplete when the next one starts is counted as corrupt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import can
import cantools
import numpy as np

from drivers.can_settings import CanSignals
from drivers.codec import Codec, FrameBatch, Framer, HealthFlag, RawChunk
from drivers.framing import SequenceUnwrapper, host_rate
from hil.inputs import resolve_path
from hil.samples import ImuSample, ImuSamples
from hil.vocabulary import Stream
from hil.units import G0

DEG = math.pi / 180.0
# DBC unit -> (what it measures, factor to SI)
UNITS: dict[str, tuple[str, float]] = {
    "rad": ("angle", 1.0), "deg": ("angle", DEG), "mrad": ("angle", 1e-3), "urad": ("angle", 1e-6),
    "rad/s": ("angular rate", 1.0), "deg/s": ("angular rate", DEG),
    "m/s": ("velocity", 1.0), "mm/s": ("velocity", 1e-3),
    "m/s^2": ("acceleration", 1.0), "m/s2": ("acceleration", 1.0), "g": ("acceleration", G0),
    "mg": ("acceleration", 1e-3 * G0),
}
_INCREMENT = {"gyro": "angle", "accel": "velocity"}
_RATE = {"gyro": "angular rate", "accel": "acceleration"}

Vec3 = tuple[float, float, float]

# Signal mappings of the shipped DBCs: configs/imu_lab_highres.dbc (the config default) and imu_j1939.dbc.
KNOWN_MAPPINGS: tuple[dict[str, Any], ...] = (
    CanSignals().model_dump(),
    {"gyro": ("ARI.PitchRate", "ARI.RollRate", "ARI.YawRate"),
     "accel": ("ACCS.LateralAcceleration", "ACCS.LongitudinalAcceleration", "ACCS.VerticalAcceleration"),
     "sync": None, "status": None, "temperature": None},
)


# One sample as a row: signal values in the DBC's units, the counter (-1: none), the status and the temperature
# (deg C, NaN: none).
FIELDS = np.dtype([("gyro", "f8", 3), ("accel", "f8", 3), ("sync_counter", "i8"), ("status", "i8"),
                   ("temperature", "f8")])


@dataclass(frozen=True, slots=True)
class CanImuFrame:
    """One sample's signal values in the DBC's units (gyro and accel x, y, z), counter, status and temperature."""

    gyro: Vec3
    accel: Vec3
    sync_counter: int | None
    status: int
    temperature: float | None = None  # deg C, when a temperature signal is configured


class CanDbcCodec(Codec[CanImuFrame]):
    """Encode samples to CAN messages and decode them back through a DBC."""

    name: ClassVar[str] = "can-dbc"
    kind: ClassVar[str] = Stream.IMU
    link: ClassVar[str] = "can"
    # the status signal's bits as the shipped lab DBC defines them (configs/imu_lab_highres.dbc)
    health_flags: ClassVar[tuple[HealthFlag, ...]] = (HealthFlag("sensor_fault", 0x1), HealthFlag("saturation", 0x2),
                                                      HealthFlag("built_in_test_failed", 0x4))
    start_up_flags: ClassVar[tuple[str, ...]] = ("built_in_test_failed",)
    unit_keys: ClassVar[tuple[str, str, str]] = ("imu.can.dbc (the accel signals' unit)",
                                                 "imu.can.dbc (the gyro signals' unit)", "imu.can.signals")

    def __init__(self, dbc: str | Path, rate_hz: float, gyro: tuple[str, str, str], accel: tuple[str, str, str],
                 sync: str | None = None, status: str | None = None, temperature: str | None = None) -> None:
        """``dbc`` is a path or a shipped DBC's name (:func:`hil.inputs.resolve_path`); ``temperature`` the signal
        of the IMU's temperature in deg C (its message one more of a sample's)."""
        super().__init__(rate_hz)
        self.db = cantools.database.load_file(str(resolve_path(dbc)))
        self.sync, self.status = sync, status
        self.quantities = [self._signal(name) for name in (*gyro, *accel)]  # (message, signal)
        self.temperature = self._signal(temperature) if temperature else None
        self.messages = list(dict.fromkeys([message for message, _ in self.quantities]
                                           + ([self.temperature[0]] if self.temperature else [])))
        self.units = [signal.unit or "" for _, signal in self.quantities]
        self.scales = [self._scale(i, name) for i, name in enumerate((*gyro, *accel))]
        for message in self.messages:
            for extra in (sync, status):
                if extra is not None and extra not in [s.name for s in message.signals]:
                    raise ValueError(f"{dbc}: message {message.name} has no signal {extra!r}, "
                                     "which must be in every configured message")
        self.sync_modulus = 1 << self.messages[0].get_signal_by_name(sync).length if sync else None
        self.messages_by_id = {(m.frame_id, m.is_extended_frame): m for m in self.messages}

    @classmethod
    def from_config(cls, imu: Any, rate_hz: float) -> CanDbcCodec:
        """The DBC and its signals are the ``imu.can`` block's (the bus's description), not options."""
        c = imu.can
        return cls(c.dbc, rate_hz, c.signals.gyro, c.signals.accel, c.signals.sync, c.signals.status,
                   c.signals.temperature)

    @classmethod
    def for_dbc(cls, dbc: str | Path, rate_hz: float, **signals: Any) -> CanDbcCodec:
        """The codec for a DBC with the given signal mapping, or the first shipped mapping that fits it."""
        if signals:
            return cls(dbc, rate_hz, **signals)
        errors = []
        for mapping in KNOWN_MAPPINGS:
            try:
                return cls(dbc, rate_hz, **mapping)
            except ValueError as exc:
                errors.append(str(exc))
        raise ValueError(f"{dbc}: none of the shipped signal mappings fits ({'; '.join(errors)}); "
                         "give gyro, accel, sync and status signals explicitly")

    def _signal(self, name: str) -> tuple[Any, Any]:
        message_name, _, signal_name = name.partition(".")
        try:
            message = self.db.get_message_by_name(message_name)
            return message, message.get_signal_by_name(signal_name)
        except KeyError:
            raise ValueError(f"DBC has no signal {name!r} (expected Message.Signal)") from None

    def _scale(self, index: int, name: str) -> float:
        """Factor from the signal's device unit to an SI increment over one sample interval."""
        group = "gyro" if index < 3 else "accel"
        unit = self.units[index]
        kind, factor = UNITS.get(unit, ("unknown", 0.0))
        if kind == _INCREMENT[group]:
            return factor
        if kind == _RATE[group]:
            return factor / self.rate_hz
        raise ValueError(f"DBC signal {name} has unit {unit!r}; a {group} signal needs a unit of "
                         f"{_INCREMENT[group]} or {_RATE[group]}: one of {', '.join(UNITS)}")

    def encode(self, record: CanImuFrame) -> list[can.Message]:
        """The CAN messages of one sample, in DBC order."""
        values = dict(zip(((m.name, s.name) for m, s in self.quantities), (*record.gyro, *record.accel)))
        if self.temperature is not None:
            values[self.temperature[0].name, self.temperature[1].name] = record.temperature or 0.0
        out = []
        for message in self.messages:
            data: dict[str, float] = {}
            for signal in message.signals:
                if (message.name, signal.name) in values:
                    data[signal.name] = values[message.name, signal.name]
                elif signal.name == self.sync:
                    data[signal.name] = record.sync_counter or 0
                elif signal.name == self.status:
                    data[signal.name] = record.status
                else:
                    low = signal.minimum if signal.minimum is not None else signal.offset
                    data[signal.name] = max(low, signal.offset)
            out.append(can.Message(arbitration_id=message.frame_id, is_extended_id=message.is_extended_frame,
                                   data=message.encode(data, padding=True)))
        return out

    def framer(self, time_scale: float | None = 1.0) -> CanFramer:
        return CanFramer(self, time_scale)

    def record(self, row: Any) -> CanImuFrame:
        counter = int(row["sync_counter"])
        temperature = float(row["temperature"])
        return CanImuFrame(tuple(row["gyro"].tolist()), tuple(row["accel"].tolist()), None if counter < 0 else counter,
                           int(row["status"]), None if math.isnan(temperature) else temperature)

    def samples(self, frames: FrameBatch) -> ImuSamples:
        scales = np.array(self.scales)
        return ImuSamples(frames.sync_index, frames.rows["gyro"] * scales[:3], frames.rows["accel"] * scales[3:],
                          np.full(len(frames), frames.host_time), frames.rows["status"].copy(),
                          frames.rows["temperature"].copy())

    @property
    def counter_modulus(self) -> int | None:
        return self.sync_modulus

    def from_sample(self, sample: ImuSample) -> CanImuFrame:
        s = self.scales
        counter = sample.sync_index % self.sync_modulus if self.sync_modulus else None
        return CanImuFrame(tuple(x / k for x, k in zip(sample.dtheta, s[:3])),
                           tuple(x / k for x, k in zip(sample.dv, s[3:])), counter, self.sent_status(sample),
                           None if math.isnan(sample.temperature_c) else sample.temperature_c)

    def csv_header(self) -> list[str]:
        units = [u.replace("/", "_").replace("^", "") for u in self.units]
        return ([f"gyro_{c}_{u}" for c, u in zip("xyz", units[:3])]
                + [f"accel_{c}_{u}" for c, u in zip("xyz", units[3:])] + ["sync_counter", "status"]
                + (["temperature_c"] if self.temperature else []))

    def csv_row(self, record: CanImuFrame) -> list[Any]:
        return [*record.gyro, *record.accel, record.sync_counter, record.status,
                *([record.temperature] if self.temperature else [])]


class CanFramer(Framer):
    """Collects the configured messages of one sample; ignores other traffic (counted as skipped bytes)."""

    def __init__(self, codec: CanDbcCodec, time_scale: float | None = 1.0) -> None:
        super().__init__()
        self.codec = codec
        self.unwrapper = SequenceUnwrapper(codec.sync_modulus, host_rate(codec.rate_hz, time_scale))
        self._pending: dict[str, dict[str, float]] = {}
        self._pending_bytes = 0
        self._counter: int | None = None

    @property
    def buffered(self) -> int:
        """Bytes of an incomplete sample held back waiting for its other messages."""
        return self._pending_bytes

    def feed_chunk(self, chunk: RawChunk) -> FrameBatch:
        codec, counters = self.codec, self.counters
        message = codec.messages_by_id.get((chunk.arbitration_id, chunk.is_extended_id))
        none = FrameBatch(np.zeros(0, dtype=FIELDS), np.zeros(0, dtype=np.int64), chunk.host_time,
                          np.zeros(0, dtype=np.int64))
        if message is None:
            counters.skipped_bytes += len(chunk.data)
            return none
        try:
            values = message.decode(chunk.data, decode_choices=False)
        except Exception:  # cantools raises several types for short or malformed data
            counters.corrupt += 1
            counters.skipped_bytes += len(chunk.data)
            return none
        counter = int(values[codec.sync]) if codec.sync else None
        if self._pending and (counter != self._counter or message.name in self._pending):
            self._drop_pending()
        self._counter = counter
        self._pending[message.name] = values
        self._pending_bytes += len(chunk.data)
        if len(self._pending) < len(codec.messages):
            return none
        return self._complete(chunk.host_time)

    def _complete(self, host_time: float) -> FrameBatch:
        """The sample of the pending messages (none when it repeats or comes late)."""
        codec, pending = self.codec, self._pending
        numbers = [float(pending[m.name][s.name]) for m, s in codec.quantities]
        status = 0
        if codec.status:
            for values in pending.values():
                status |= int(values[codec.status])
        counter = -1 if self._counter is None else self._counter
        temperature = float(pending[codec.temperature[0].name][codec.temperature[1].name]) if codec.temperature \
            else math.nan
        row = np.array([(numbers[:3], numbers[3:], counter, status, temperature)], dtype=FIELDS)
        index, missing, repeated = self.unwrapper.next_many(None if self._counter is None else np.array([counter]),
                                                            np.array([host_time]))
        deliver = self.unwrapper.count_many(self.counters, missing, repeated)
        if not deliver[0]:
            self.counters.skipped_bytes += self._pending_bytes
        size = np.array([self._pending_bytes])
        self._pending, self._pending_bytes = {}, 0
        return FrameBatch(row[deliver], index[deliver], host_time, size[deliver])

    def _drop_pending(self) -> None:
        self.counters.corrupt += 1
        self.counters.skipped_bytes += self._pending_bytes
        self._pending, self._pending_bytes = {}, 0

    def reset(self) -> None:
        if self._pending:
            self._drop_pending()
