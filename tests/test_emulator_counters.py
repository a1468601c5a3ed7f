"""The emulated devices' counters as a lab's hardware has them: each from its own start, restarted by a
power cycle. Expectations are worked out by hand from the configs."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from test_faults import capture

from drivers.can_dbc import CanDbcCodec
from drivers.tts1 import Tts1Codec
from drivers.kvh1750 import Kvh1750Codec
from drivers.registry import imu_codec
from emulators.bench import device_streams
from emulators.clocks import counter_starts, imu_counter_modulus
from hil.config import ConfigError, parse_config

SWING = Path(__file__).resolve().parents[1] / "configs" / "emulated_swing.yaml"


def config(imu: dict | None = None, turntable: dict | None = None, seed: int = 7, rate_hz: float = 200.0):
    """configs/emulated_swing.yaml with ``imu`` and ``turntable`` keys replaced and the table at 200 Hz."""
    cfg = yaml.safe_load(SWING.read_text())
    cfg["trial"].update(seed=seed, duration_s=1.0)
    cfg["imu"].update({"rate_hz": rate_hz, **(imu or {})})
    cfg["turntable"].update(turntable or {})
    return parse_config(cfg)


def emitted(cfg, name: str, duration: float) -> list:
    """Every emission of one device over ``duration`` s, the powered-off ones included."""
    servo, streams = device_streams(cfg, duration)
    stream, out = streams[name], []
    while not stream.done():
        out.append(stream.pop(servo))
    return out


def imu_counters(cfg, duration: float) -> list[int]:
    codec = imu_codec(cfg.imu, cfg.imu_rate_hz)
    return [int(codec.sequences(codec.framer().feed_bytes(e.payload).rows)[0])  # each frame on its own
            for e in emitted(cfg, "imu", duration) if e.powered]


def table_counters(cfg, duration: float) -> list[int]:
    return [Tts1Codec().decode(e.payload).sync_counter for e in emitted(cfg, "turntable_data", duration) if e.powered]


def test_each_counter_starts_where_configured_and_wraps_at_its_protocols_modulus():
    cfg = config({"timing": {"counter_start": 100}}, {"timing": {"counter_start": 5000}}, rate_hz=1000.0)
    assert imu_counters(cfg, 0.05) == [(100 + k) % 128 for k in range(1, 51)]  # 1 kHz: ticks 1..50
    assert table_counters(cfg, 0.05) == [5000 + 5 * k for k in range(1, 11)]  # every 5th pulse
    xsens = config({"protocol": "xsens-mtdata2", "timing": {"counter_start": 65530}})
    assert imu_counters(xsens, 0.05) == [(65530 + k) % 65536 for k in range(1, 11)]


def test_can_frames_carry_the_counter_modulo_the_dbc_sync_signal():
    cfg = config({"protocol": "can-dbc", "can": {"interface": "virtual", "channel": "counters"},
                  "timing": {"counter_start": (1 << 24) - 3}})
    assert imu_counter_modulus(cfg) == 1 << 24  # SyncCounter: 24 bits in configs/imu_lab_highres.dbc
    frames = [e.payload for e in emitted(cfg, "imu", 0.025)]
    dbc = CanDbcCodec.from_config(cfg.imu, cfg.imu_rate_hz)
    counters = [{dbc.messages_by_id[(m.arbitration_id, m.is_extended_id)].decode(m.data)["SyncCounter"]
                 for m in frame} for frame in frames]
    assert counters == [{c} for c in ((1 << 24) - 2, (1 << 24) - 1, 0, 1, 2)]


def test_the_counter_start_changes_the_counter_only():
    """Truth and time follow the tick: the increments, times and pulses are those of a start at 0."""
    plain, late = (emitted(config({"timing": {"counter_start": c}}), "imu", 0.1) for c in (0, 77))
    codec = Kvh1750Codec(200.0)
    assert [(e.tick, e.t) for e in late] == [(e.tick, e.t) for e in plain] == [(k, k / 200) for k in range(1, 21)]
    for a, b in zip(plain, late):
        ra, rb = codec.decode(a.payload), codec.decode(b.payload)
        assert (ra.gyro, ra.accel) == (rb.gyro, rb.accel) and rb.sequence == (ra.sequence + 77) % 128


def test_drawn_starts_are_distinct_per_device_reproducible_and_follow_the_seed():
    starts = {seed: counter_starts(config(seed=seed)) for seed in range(20)}
    assert all(0 <= imu < 128 and 0 <= table < 1 << 20 and imu != table for imu, table in starts.values())
    assert len(set(starts.values())) == 20 and starts[7] == counter_starts(config(seed=7))
    assert len({table for _, table in starts.values()}) == 20 and max(t for _, t in starts.values()) > 1000
    imu, table = starts[7]
    assert imu_counters(config(), 0.02) == [(imu + k) % 128 for k in range(1, 5)]
    assert table_counters(config(), 0.02) == [table + k for k in range(1, 5)]
    xsens = [counter_starts(config({"protocol": "xsens-mtdata2"}, seed=s))[0] for s in range(20)]
    assert all(0 <= s < 65536 for s in xsens) and max(xsens) > 128
    assert counter_starts(config({"timing": {"counter_start": 3}}, {"timing": {"counter_start": 4}})) == (3, 4)
    assert counter_starts(config({"timing": {"counter_start": 3}}, seed=7)) == (3, table)


POWER_CYCLE = {"power_cycle_at_s": 0.5, "power_cycle_s": 0.25}


def test_a_power_cycle_silences_the_device_then_its_counter_restarts_from_zero():
    cfg = config({"timing": {"counter_start": 10}, "faults": POWER_CYCLE},
                 {"timing": {"counter_start": 7}, "faults": POWER_CYCLE}, rate_hz=1000.0)
    # IMU at 1 kHz: ticks 500..749 (0.5 s to 0.75 s) silent; tick 750 carries 0
    imu = [e for e in emitted(cfg, "imu", 1.0) if e.powered]
    assert [round(e.t * 1000) for e in imu] == list(range(1, 500)) + list(range(750, 1001))
    assert imu_counters(cfg, 1.0) == [(10 + k) % 128 for k in range(1, 500)] + [k % 128 for k in range(251)]
    # table at 200 Hz on every 5th pulse: ticks 100..149 silent; tick 150 carries 0, then 5, 10 ...
    table = [e for e in emitted(cfg, "turntable_data", 1.0) if e.powered]
    assert [round(e.t * 200) for e in table] == list(range(1, 100)) + list(range(150, 201))
    assert table_counters(cfg, 1.0) == [7 + 5 * k for k in range(1, 100)] + [5 * k for k in range(51)]


def test_a_power_cycle_on_the_ports_is_silence_counted_as_power_cycled():
    cfg = config({"timing": {"counter_start": 10}, "faults": POWER_CYCLE},
                 {"timing": {"counter_start": 0}, "faults": {"power_cycle_at_s": 0.2, "power_cycle_s": 0.0}})
    stats, out = capture(cfg, duration=1.0)
    kvh, tts1 = Kvh1750Codec(200.0), Tts1Codec()
    imu = [kvh.decode(bytes(out["imu"][i:i + 36])).sequence for i in range(0, len(out["imu"]), 36)]
    table = [tts1.decode(bytes(out["turntable_data"][i:i + 24])).sync_counter
             for i in range(0, len(out["turntable_data"]), 24)]
    # 200 Hz: ticks 100..149 silent, 150 carries 0; the table restarts at tick 40 without a silence
    assert imu == [(10 + k) % 128 for k in range(1, 100)] + list(range(51))
    assert table == list(range(1, 40)) + list(range(161))
    assert stats.devices["imu"].faults["power_cycled"] == 50 and stats.devices["imu"].frames == 150
    assert stats.devices["turntable_data"].faults["power_cycled"] == 0


def test_negative_counter_starts_and_power_cycles_are_refused():
    with pytest.raises(ConfigError, match="imu.timing.counter_start"):
        config({"timing": {"counter_start": -1}})
    with pytest.raises(ConfigError, match="turntable.faults.power_cycle_s"):
        config(turntable={"faults": {"power_cycle_at_s": 1.0, "power_cycle_s": -1.0}})
