"""Fault injection: each kind, switched on alone, shows in the driver's counters with the injected count."""

from __future__ import annotations

import json
import math
import os
import threading
import time

import numpy as np
import pytest
import yaml
from tests.helpers import Decoding, from_zero
from test_emulated_devices import read_raw

from drivers.framing import SequenceUnwrapper
from drivers.kvh1750 import Kvh1750Codec, KvhFrame
from drivers.reader import DeviceReader
from drivers.transport import SerialTransport
from drivers.tts1 import Status, Tts1Codec
from emulators.clocks import DeviceClock
from emulators.faults import ByteDamage, CanDamage, FaultInjector
from emulators.in_process import EmulatorThread
from emulators.process import EmulatorRun, spawn_emulator
from hil.config import Config, DeviceTiming, FaultConfig, parse_config

RATE = 200.0
DURATION = 2.0
N = int(RATE * DURATION)
SWING = {"outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
         "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
         "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6}}


def trial(duration=DURATION, imu=None, turntable=None, seed=5) -> dict:
    return {"trial": {"name": "faults", "duration_s": duration, "rate_hz": RATE, "seed": seed},
            "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
            "turntable": from_zero({"latch_delay_us": 50, "motion": {"kind": "swing", "axes": SWING}, **(turntable or {})}),
            "imu": from_zero(imu)}


def capture(cfg: dict | Config, speed: float | None = None, duration: float | None = None):
    """Run the emulator to its end; its stats and the bytes each pty delivered."""
    with EmulatorThread(cfg if isinstance(cfg, Config) else parse_config(cfg), speed, duration) as emu:
        out = {k: bytearray() for k in ("imu", "turntable_data")}
        readers = [threading.Thread(target=read_raw, args=(emu.ports[k], buf)) for k, buf in out.items()]
        for r in readers:
            r.start()
        stats = emu.join()
        for r in readers:
            r.join(10)
    return stats, out


def framed(codec, data: bytes):
    framer = codec.framer()
    return framer.counters, framer.feed_bytes(data, math.nan)


def imu_counters(fault: dict):
    stats, out = capture(trial(imu={"faults": fault}))
    counters, decoded = framed(Kvh1750Codec(RATE), out["imu"])
    ends = decoded.sync_index[0] - 1 + N - decoded.sync_index[-1]  # losses at either end leave no gap
    return stats.devices["imu"].faults, counters, ends


def test_dropped_frames_are_the_missing_frames():
    injected, counters, ends = imu_counters({"drop_rate": 0.02, "drop_burst": 3})
    assert injected["dropped"] > 10
    assert counters.missing + ends == injected["dropped"] and counters.frames == N - injected["dropped"]
    assert counters.corrupt == 0 and counters.skipped_bytes == 0


def test_corrupted_frames_fail_their_crc_and_are_skipped_whole():
    injected, counters, ends = imu_counters({"corrupt_byte_rate": 0.002})
    damaged = injected["corrupted"]
    assert damaged > 5
    assert counters.frames == N - damaged and counters.missing + ends == damaged
    assert counters.skipped_bytes == 36 * damaged
    assert 0 < counters.corrupt <= damaged  # a flip in the header hides the frame rather than failing its CRC


def test_truncated_frames_are_lost_and_their_bytes_skipped():
    injected, counters, ends = imu_counters({"truncate_rate": 0.03})
    cut = injected["truncated"]
    assert cut > 5
    assert counters.frames == N - cut and counters.missing + ends == cut
    assert 0 < counters.corrupt <= cut


def test_duplicated_frames_are_counted_and_not_delivered_twice():
    injected, counters, _ = imu_counters({"duplicate_rate": 0.03})
    assert injected["duplicated"] > 5
    assert counters.duplicates == injected["duplicated"]
    assert counters.frames == N and counters.missing == 0


def test_reordered_frames_are_counted_out_of_order():
    injected, counters, _ = imu_counters({"reorder_rate": 0.03})
    assert injected["reordered"] > 5
    assert counters.out_of_order == injected["reordered"]
    assert counters.frames == N - injected["reordered"] and counters.missing == injected["reordered"]


def test_table_faults_show_in_the_tts1_counters():
    stats, out = capture(trial(turntable={"faults": {"drop_rate": 0.01, "duplicate_rate": 0.02}}))
    injected = stats.devices["turntable_data"].faults
    counters, decoded = framed(Tts1Codec(), out["turntable_data"])
    assert counters.missing + decoded.sync_index[0] - 1 + N - decoded.sync_index[-1] == injected["dropped"] > 0
    assert counters.duplicates == injected["duplicated"] > 0
    assert stats.devices["imu"].faults["dropped"] == 0


def test_faults_are_reproducible_from_the_seed():
    fault = FaultConfig(drop_rate=0.1, corrupt_byte_rate=0.01, truncate_rate=0.1, duplicate_rate=0.1, reorder_rate=0.1)
    frames = [bytes([k]) * 36 for k in range(200)]

    def run(seed):
        inj = FaultInjector(fault, ByteDamage(), seed, 0)
        return [inj.frames(f) for f in frames], dict(inj.counts)

    assert run(3) == run(3) and run(3) != run(4)


def test_can_damage_loses_or_shortens_one_message():
    import can

    messages = [can.Message(arbitration_id=0x100 + i, data=bytes(8), is_extended_id=False) for i in range(6)]
    rng = np.random.Generator(np.random.PCG64(1))
    assert CanDamage().corrupt(messages, 0.0, rng) is None
    assert len(CanDamage().corrupt(messages, 1.0, rng)) == 0
    cut = CanDamage().truncate(messages, rng)
    assert len(cut) == 6 and sum(len(m.data) for m in cut) < 48


def test_unplug_closes_the_pty_and_the_session_reconnects_through_its_stable_link():
    # The table's 32-bit counter says exactly how many frames were lost, however late they come back.
    cfg = parse_config(trial(duration=1.5, turntable={"faults": {"unplug_at_s": 0.5, "unplug_s": 0.25}}))
    with EmulatorThread(cfg) as emu:
        link = emu.ports["turntable_data"]
        assert os.path.islink(link) and os.readlink(link).startswith("/dev/pts/")
        assert emu.ports["imu"].startswith("/dev/pts/")  # a device that never unplugs keeps its pty name
        sinks = {"imu": Decoding(Kvh1750Codec(RATE)), "turntable_data": Decoding(Tts1Codec())}
        sessions = {name: DeviceReader(SerialTransport(emu.ports[name], 921600, name), [sink],
                                       backoff_s=(0.02, 0.1)).start() for name, sink in sinks.items()}
        table = sinks["turntable_data"]
        try:
            deadline = time.monotonic() + 10
            while table.counters.frames + table.counters.missing < 300 and time.monotonic() < deadline:
                time.sleep(0.02)
        finally:
            # stopped before the run ends: a session left reopening a bare /dev/pts/N could land on
            # another program's pty that took the number
            for s in sessions.values():
                s.stop()
        outages = {name: s.outages for name, s in sessions.items()}
        stats = emu.join()
        assert not os.path.lexists(link)
    injected = stats.devices["turntable_data"].faults
    assert injected["unplugs"] == 1 and injected["unplugged"] == 50
    # one unplug; on a loaded host the reader may reopen the new pty while the emulator is still
    # setting it up and see one more short outage
    assert outages["imu"] == 0 and outages["turntable_data"] in (1, 2)
    # 50 frames lost while unplugged (more only if the host flushed some while it reopened the port)
    head = {name: sink.samples[0].sync_index - 1 for name, sink in sinks.items()}
    assert table.counters.gaps == 1 and table.counters.missing >= 50
    assert head["turntable_data"] + table.counters.frames + table.counters.missing == 300
    imu = sinks["imu"].counters
    assert head["imu"] + imu.frames == 300 and imu.missing == 0


def test_stats_go_to_stderr_and_the_stats_file(tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump(trial(duration=0.5, imu={"faults": {"drop_rate": 0.1}})))
    stats_file = tmp_path / "stats.json"
    proc, ports = spawn_emulator(config, tmp_path / "ports.json", EmulatorRun(wait_readers=True, stats_file=stats_file))
    readers = [threading.Thread(target=read_raw, args=(ports[k], bytearray())) for k in ("imu", "turntable_data")]
    for r in readers:
        r.start()
    assert proc.wait(20) == 0
    for r in readers:
        r.join(5)
    stats = json.loads(stats_file.read_text())
    assert stats["pulses"] == 100 and not stats["stopped"]
    imu = stats["devices"]["imu"]
    assert imu["frames"] + imu["faults"]["dropped"] == 100 and imu["faults"]["dropped"] > 0
    assert set(imu) == {"frames", "faults", "latency_p50_ms", "latency_p99_ms", "lost_unread"} and imu["lost_unread"] == 0


def test_unwrapper_tells_repeats_and_late_frames_from_wraps():
    unwrapper = SequenceUnwrapper(128, rate_hz=200.0)
    index, missing, repeated = unwrapper.next_many(np.array([5, 7, 6, 7, 7]),
                                                   np.array([0.0, 0.01, 0.01, 0.01, 0.01 + 128 / 200.0]))
    # then late, repeated, and a whole period later: a wrap
    assert list(zip(index.tolist(), missing.tolist())) == [(5, 0), (7, 1), (6, -1), (7, -1), (135, 127)]
    assert repeated.tolist() == [False, False, False, True, False]
    codec = Kvh1750Codec(RATE)
    frames = [codec.encode(KvhFrame((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0x77, i, 25)) for i in (1, 2, 2, 4, 3, 5)]
    counters, decoded = framed(codec, b"".join(frames))
    assert decoded.sync_index.tolist() == [1, 2, 4, 5]
    assert (counters.duplicates, counters.out_of_order, counters.missing) == (1, 1, 1)
    assert counters.skipped_bytes == 72


def test_device_clock_jitter_drift_and_free_running():
    rng = np.random.Generator(np.random.PCG64(0))
    k = np.arange(1, 20001)
    jittery = DeviceClock(RATE, 50e-6, DeviceTiming(latch_jitter_us=20.0))
    offsets = jittery.latch_times(k, rng) - (k / RATE + 50e-6)
    assert np.std(offsets) == pytest.approx(20e-6, rel=0.03) and abs(np.mean(offsets)) < 1e-6
    free = DeviceClock(RATE, 0.0, DeviceTiming(clock_drift_ppm=100.0, free_running=True))
    # 100 ppm fast: its 200 Hz ticks come every 5 ms / 1.0001 of true time; 60 s hold 12001 ticks.
    assert free.ticks(60.0) == 12001 and free.tick_times(np.array([12001]))[0] == pytest.approx(60.005 / 1.0001)
    assert free.device_time(np.array([100.0]))[0] == pytest.approx(100.01)
    synced = DeviceClock(RATE, 0.0, DeviceTiming(clock_drift_ppm=100.0))
    assert synced.ticks(60.0) == 12000 and synced.device_time(np.array([1.0]))[0] == pytest.approx(1.0001)


def test_a_clock_latching_every_fifth_pulse_counts_the_pulses():
    table = DeviceClock(5 * RATE, 50e-6, DeviceTiming(), counts_per_tick=5)  # every fifth pulse of 1 kHz
    k = np.arange(1, 4)
    assert table.ticks(DURATION) == N and table.counters(k).tolist() == [5, 10, 15]
    np.testing.assert_allclose(table.latch_times(k, np.random.default_rng(0)), table.counters(k) / 1000.0 + 50e-6,
                               rtol=0, atol=1e-15)


def test_a_table_under_a_faster_imu_latches_every_nth_pulse_and_counts_them():
    stats, out = capture(trial(imu={"rate_hz": 5 * RATE}, turntable={"faults": {"drop_rate": 0.02}}))
    counters, decoded = framed(Tts1Codec(pulses_per_frame=5), out["turntable_data"])
    sent = decoded.sync_index.tolist()
    assert set(sent) < set(range(5, 5 * N + 1, 5))  # the pulse count at every fifth pulse of 1 kHz
    ends = (sent[0] - 5 + 5 * N - sent[-1]) // 5  # frames lost at either end leave no gap
    assert counters.missing + ends == stats.devices["turntable_data"].faults["dropped"] > 0
    assert stats.devices["imu"].frames == stats.pulses == 5 * N


def test_a_free_running_table_under_a_faster_imu_counts_its_own_latches():
    stats, out = capture(trial(imu={"rate_hz": 5 * RATE}, turntable={"timing": {"free_running": True}}))
    _, decoded = framed(Tts1Codec(), out["turntable_data"])
    assert decoded.sync_index.tolist() == list(range(1, N + 1))
    assert stats.devices["imu"].frames == stats.pulses == 5 * N


def test_write_jitter_delays_every_paced_frame_by_up_to_jitter_ms():
    stats, _ = capture(trial(duration=0.5, imu={"faults": {"jitter_ms": 3.0}}), speed=1.0)
    imu = stats.devices["imu"]
    assert imu.faults["delayed"] == imu.frames == 100
    # U(0, 3 ms) on top of 0.39 ms of wire time: the slowest percent is late by nearly 3 ms or more
    assert imu.latency_p99_ms >= 2.5 and stats.devices["turntable_data"].faults["delayed"] == 0


def test_a_free_running_table_ticks_on_its_own_drifting_clock():
    stats, out = capture(trial(turntable={"timing": {"free_running": True, "clock_drift_ppm": 5000.0}}))
    _, decoded = framed(Tts1Codec(), out["turntable_data"])
    # 2 s on a clock 0.5 % fast at 200 Hz: 402 frames, each flagged free-running; the IMU keeps the pulses
    assert decoded.sync_index.tolist() == list(range(1, 403))
    assert all(decoded.rows["status"] & Status.FREE_RUNNING)
    assert stats.devices["imu"].frames == 400 and stats.pulses == 400
