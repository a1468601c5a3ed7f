"""The emulated table's servo and the emulated Acutrol on it, driven by the Acutrol controller over TCP."""

from __future__ import annotations

import math
import socket
import threading
import time

import numpy as np
import pytest
from tests.helpers import from_zero
from test_emulated_devices import read_raw

from drivers.acl import AclCommand, ReplyReader
from drivers.acutrol_controller import AcutrolController, AcutrolOptions
from drivers.kvh1750 import Kvh1750Codec
from drivers.table_controller import MOTION_MODES, InterlockError, LimitError, TableError
from drivers.tts1 import Mode, Status, Tts1Codec
from emulators.acutrol_table import AcutrolTable
from emulators.clocks import DeviceClock
from emulators.in_process import EmulatorThread
from emulators.motion import motion_from_config
from emulators.servo import Servo
from emulators.sources import TableSource
from emulators.truth import Truth
from hil.config import parse_config
from hil.frames import Earth, TableGeometry
from hil.units import ARCSEC

RATE = 200.0
DEG = math.pi / 180.0
LIMITS = {"position_min_deg": [-180, -60, -180], "position_max_deg": [180, 60, 180],
          "rate_dps": [30, 20, 40], "accel_dps2": [50, 50, 50]}
CENTERS = {"outer": 5.0, "middle": 2.0, "inner": 10.0}


def static_config(duration=4.0, **turntable):
    axes = {axis: {"center_deg": c} for axis, c in CENTERS.items()}
    return parse_config({
        "trial": {"name": "servo", "duration_s": duration, "rate_hz": RATE, "seed": 2},
        "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
        "turntable": from_zero({"latch_delay_us": 50, "limits": LIMITS, "motion": {"kind": "static", "axes": axes},
                                **turntable}),
        "imu": from_zero({}),
    })


def servo_at_rest() -> Servo:
    cfg = static_config()
    return Servo(cfg.turntable, RATE, motion_from_config(cfg.turntable.motion))


def ask(servo: Servo, line: str):
    """The emulated Acutrol's framed reply to one message, decoded."""
    (reply,) = ReplyReader().feed(AcutrolTable(servo, AcutrolOptions()).answer(line.encode()))
    return reply


def at(servo: Servo, t: float, column: int) -> tuple[float, float]:
    angles, rates = servo.motion(np.array([t]))
    return angles[0, column] / DEG, rates[0, column] / DEG


def test_position_move_is_a_trapezoid_at_the_limits():
    servo = servo_at_rest()
    servo.commit(1.0)  # frames up to t = 1 s are out: the change starts at the next pulse
    assert ask(servo, ":Demand:Position 2,30").ok
    t0 = 1.0 + 1 / RATE
    # middle: 2 -> 30 deg at 20 deg/s and 50 deg/s^2: 0.4 s ramps cover 4 deg each, 20 deg cruise take 1 s.
    assert at(servo, t0 - 1e-9, 1) == pytest.approx((2.0, 0.0))
    assert at(servo, t0 + 0.4, 1) == pytest.approx((6.0, 20.0))
    assert at(servo, t0 + 1.4, 1) == pytest.approx((26.0, 20.0))
    assert at(servo, t0 + 1.8, 1) == pytest.approx((30.0, 0.0), abs=1e-9)
    assert at(servo, t0 + 5.0, 1) == pytest.approx((30.0, 0.0), abs=1e-9)
    assert at(servo, t0 + 0.7, 0) == pytest.approx((5.0, 0.0))  # the other axes hold


def test_rate_mode_halts_exactly_at_a_position_limit():
    servo = servo_at_rest()
    assert ask(servo, ":D:R 2,20;:M:R 2").ok
    # From 2 deg at rest: 4 deg ramping up, 4 deg braking, so 50 deg cruising at 20 deg/s; halts at 60.
    assert at(servo, 0.4, 1) == pytest.approx((6.0, 20.0))
    assert at(servo, 2.9, 1) == pytest.approx((56.0, 20.0))
    assert at(servo, 3.3, 1) == pytest.approx((60.0, 0.0), abs=1e-9)
    assert at(servo, 10.0, 1) == pytest.approx((60.0, 0.0), abs=1e-9)
    status = int(servo.motion.status(np.array([10.0]), servo.limits)[0])
    assert status & Status.LIMIT_REACHED and not status & Status.MOVING and status >> 5 == Mode.RATE


def test_commands_outside_the_limits_or_with_open_interlocks_are_refused():
    servo = servo_at_rest()
    refused = ask(servo, ":Demand:Position 2,95")
    assert refused.error == 3 and "outside the middle limits" in refused.text
    assert ask(servo, ":Demand:Rate 1,-41").error == 3
    assert ask(servo, ":Demand:Oscillator 1,5,1,0").error == 3  # 197 deg/s^2
    assert ask(servo, ":Interlock:Open 3").ok
    assert ask(servo, ":Mode 3,Position").error == 4
    assert ask(servo, ":Interlock? 1;:Interlock? 2;:Interlock? 3").text == "Close;Close;Open"
    assert servo.revision == 1  # only the interlock change re-planned the motion


class Readers:
    """Read the IMU and table ptys into byte buffers until the emulator closes them."""

    def __init__(self, ports: dict) -> None:
        self.imu, self.table = bytearray(), bytearray()
        self.threads = [threading.Thread(target=read_raw, args=(ports[k], buf))
                        for k, buf in (("imu", self.imu), ("turntable_data", self.table))]
        for t in self.threads:
            t.start()

    def table_frames(self):
        return Tts1Codec().framer().feed_bytes(bytes(self.table))

    def wait_table_frames(self, n: int) -> None:
        deadline = time.monotonic() + 10
        while len(self.table) < 24 * n:
            assert time.monotonic() < deadline
            time.sleep(0.01)

    def wait_swing_frames(self, n: int) -> None:
        deadline = time.monotonic() + 20
        while np.count_nonzero(self.table_frames().rows["status"] >> 5 == Mode.SYNTHESIS) < n:
            assert time.monotonic() < deadline
            time.sleep(0.02)

    def join(self) -> None:
        for t in self.threads:
            t.join(10)


def test_a_swing_armed_through_the_client_is_what_tts1_and_the_imu_report():
    cfg = static_config(duration=8.0)
    with EmulatorThread(cfg, speed=5.0) as emu:
        readers = Readers(emu.ports)
        readers.wait_table_frames(100)
        with AcutrolController(emu.ports["turntable_cmd"], cfg.turntable.limits) as client:
            assert client.identify().startswith("turntable-hil")
            client.apply_limits()
            client.demand_position("inner", 10.0)
            client.demand_oscillator("inner", 5.0, 0.25, 0.0)
            client.set_mode("inner", "synthesis")
            with pytest.raises(LimitError):
                client.demand_position("middle", 61.0)
            with pytest.raises(TableError, match=r"error 3 \(parameter out of range\)"):  # the table refuses it too
                client.send(AclCommand("Demand:Position", ("2", 61.0)))
            readers.wait_swing_frames(200)
            assert client.query("Mode", "1") == "Synthesis"
        # closing the client switched the table Off: it brakes from the next pulse on
        emu.join()
        readers.join()
    frames = readers.table_frames()
    modes = (frames.rows["status"] >> 5).tolist()
    index = frames.sync_index.tolist()
    k_s = index[modes.index(Mode.SYNTHESIS)]
    k_off = next((k for k, m in zip(index, modes) if m == Mode.OFF), index[-1] + 1)
    assert k_s > 100 and k_off > k_s + 200 and all(m == Mode.POSITION for m in modes[:k_s - 1])
    assert index[0] == 1
    rows = frames.rows[:k_off - 1]
    latch = np.array(index[:k_off - 1]) / RATE + 50e-6
    t_s = k_s / RATE
    swing = 10.0 + 5.0 * np.sin(2 * math.pi * 0.25 * (latch - t_s))
    expected_inner = np.where(latch >= t_s, swing, 10.0)
    inner = rows["angles_udeg"][:, 2] * 1e-6
    assert np.max(np.abs(inner - expected_inner)) <= 0.5e-6
    assert (rows["angles_udeg"][:, :2] == (5_000_000, 2_000_000)).all()

    # The IMU senses that motion: its increments equal the truth of the same piecewise swing.
    def motion(t):
        t = np.asarray(t, dtype=float)
        on = t >= t_s
        arg = 2 * math.pi * 0.25 * (t - t_s)
        angles = np.tile([5.0, 2.0, 10.0], (len(t), 1)) * DEG
        rates = np.zeros((len(t), 3))
        angles[on, 2] += 5.0 * DEG * np.sin(arg[on])
        rates[on, 2] = 5.0 * DEG * 2 * math.pi * 0.25 * np.cos(arg[on])
        return angles, rates

    motion.breaks = lambda t0, t1: np.array([t_s]) if t0 < t_s < t1 else np.empty(0)
    codec = Kvh1750Codec(RATE)
    imu = codec.samples(codec.framer().feed_bytes(bytes(readers.imu))).dtheta[:k_off - 1]
    n = len(imu)
    truth = Truth(Earth.from_degrees(32.0, 0.0), TableGeometry.from_config(cfg.turntable), motion)
    dtheta, _ = truth.increments(0.0, np.arange(1, n + 1) / RATE)
    np.testing.assert_allclose(imu, dtheta, rtol=2e-7, atol=1e-13)


def test_an_interlock_trip_shows_in_tts1_and_in_the_acl_replies():
    cfg = static_config(duration=4.0, interlock_trip_at_s=1.0)
    with EmulatorThread(cfg, speed=2.0) as emu:
        readers = Readers(emu.ports)
        readers.wait_table_frames(260)
        with AcutrolController(emu.ports["turntable_cmd"], cfg.turntable.limits) as client:
            assert not client.interlocks_closed("inner")
            assert client.query("Interlock", "1") == "Fault"
            assert client.identify() and int(client.query("*STB")) == 0x41  # MSS and the interlock summary bit
            with pytest.raises(InterlockError):
                client.set_mode("inner", "position")
            with pytest.raises(TableError, match=r"error 4 "):
                client.send(AclCommand("Mode", ("1", "Position")))
            with pytest.raises(TableError, match=r"error 4 .*interlock fault latched"):
                client.send(AclCommand("Interlock:Close", ("ALL",)))
            client.send(AclCommand("Interlock:Reset"), AclCommand("Interlock:Close", ("ALL",)))
            assert client.interlocks_closed("inner")
        emu.join()
        readers.join()
    frames = readers.table_frames()
    status = dict(zip(frames.sync_index.tolist(), frames.rows["status"].tolist()))
    assert status[199] == (Status.INTERLOCKS_CLOSED | Mode.POSITION << 5)
    assert status[200] == (Status.FAULT | Mode.OFF << 5)  # tripped at the pulse of t = 1 s
    assert status[max(status)] & Status.INTERLOCKS_CLOSED and not status[max(status)] & Status.FAULT


def test_the_command_port_answers_bad_commands_with_framed_errors_and_is_loopback_only():
    cfg = static_config(duration=2.0)
    # at real time: as fast as possible, the emulated trial can end (and close its port) before the replies
    with EmulatorThread(cfg, speed=1.0, wait_readers=False) as emu:
        host, port = emu.ports["turntable_cmd"].removeprefix("socket://").split(":")
        assert host == "127.0.0.1"
        with socket.create_connection((host, int(port)), timeout=2) as conn:
            conn.sendall(b":Spin 1\r\n:Mode 4,Position\n:Mode? ALL\n:mode? 1;:M? 2;:MODE? 3\n")
            reader, replies = ReplyReader(), []
            while len(replies) < 4:
                replies += reader.feed(conn.recv(4096))
        assert [(r.error, r.text) for r in replies[:3]] == [
            (2, "unknown command ':Spin 1' ('Spin' is not under the root)"),
            (3, "axis '4' in ':Mode 4,Position': the table has axes 1..3"),
            (3, "axis 'ALL' in ':Mode? ALL': the table has axes 1..3, ALL only in commands")]
        assert replies[3].ok and replies[3].text == "Position;Position;Position"
        emu.join()


@pytest.mark.parametrize("kind, axis", [("static", {"center_deg": 1.0}),
                                         ("swing", {"amplitude_deg": 5.0, "period_s": 8.0, "center_deg": 1.0}),
                                         ("rate", {"rate_dps": 2.0})])
def test_the_table_performs_each_motion_kind_in_the_mode_named_for_it(kind, axis):
    cfg = parse_config({
        "trial": {"name": "servo", "duration_s": 4.0, "rate_hz": RATE, "seed": 2},
        "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
        "turntable": {"limits": LIMITS, "motion": {"kind": kind, "axes": dict.fromkeys(CENTERS, axis)}},
    })
    servo = Servo(cfg.turntable, RATE, motion_from_config(cfg.turntable.motion))
    word = MOTION_MODES[kind].capitalize()
    assert ask(servo, ":Mode? 1;:Mode? 2;:Mode? 3").text == ";".join([word] * 3)


def test_the_table_reports_the_true_angles_minus_the_zero_offsets():
    # true gimbal angles (5, 2, 10) deg; zero offsets (36, -72, 18) arcsec = (0.01, -0.02, 0.005) deg, the true
    # angle minus the encoder reading: the encoders read (4.99, 2.02, 9.995) deg
    cfg = static_config(zero_offset_arcsec=[36.0, -72.0, 18.0])
    servo = Servo(cfg.turntable, RATE, motion_from_config(cfg.turntable.motion))
    truth = Truth(Earth.from_degrees(32.0, 0.0), TableGeometry.from_config(cfg.turntable), servo.motion)
    clock = DeviceClock(RATE, 50e-6, cfg.turntable.timing)
    source = TableSource(clock, 2, np.array(cfg.turntable.zero_offset_arcsec) * ARCSEC)
    codec = Tts1Codec()
    frames = [codec.decode(e.payload) for e in source.compute(np.arange(1, 6), truth, servo)]
    assert {f.angles_udeg for f in frames} == {(4_990_000, 2_020_000, 9_995_000)}
    assert np.allclose(truth.angles(np.array([0.1]))[0] / DEG, [5.0, 2.0, 10.0])  # the IMU moves with the truth
    replies = ask(servo, ":read:pos? 1;pos? 2;pos? 3").text  # axis 1 inner, 2 middle, 3 outer
    assert [float(v) for v in replies.split(";")] == [9.995, 2.02, 4.99]


def test_the_servo_performs_a_calibration_schedule_commanded_live_within_its_limits():
    """Position moves with dwells, then rate plateaus of both signs about each axis, as the calibration
    harness commands them: each command at the pulse after what was emitted, the motion within the
    rate and acceleration limits, and the IMU's truth turning with the table."""
    from hil.estimation.calibration_schedule import default_schedule

    servo = servo_at_rest()
    schedule = default_schedule(positions=6, dwell_s=1.0, settle_s=0.5, rate=10 * DEG, plateau_s=4.0)
    t, holds, plateaus = 0.0, [], []
    for step in list(schedule.dwells) + list(schedule.plateaus):
        target = np.clip(np.array(step.angles) / DEG, [-180, -60, -180], [180, 60, 180])
        for k, gimbal in enumerate(("3", "2", "1")):  # axis numbers: outer 3, middle 2, inner 1
            assert ask(servo, f":Demand:Position {gimbal},{float(target[k])!r};:Mode:Position {gimbal}").ok
        start = servo.next_pulse_time()
        t = start + 8.0  # every move of this schedule ends within 8 s at 30/20/40 deg/s
        holds.append((t, target))
        servo.commit(t + 1.0)  # a dwell emitted
        if hasattr(step, "rate"):
            axis = ("3", "2", "1")[step.axis]
            assert ask(servo, f":Mode {axis},Rate;:Demand:Rate {axis},{step.rate / DEG!r}").ok
            begin = servo.next_pulse_time()
            plateaus.append((begin + 0.5, step.axis, step.rate / DEG))  # 10 deg/s at 50 deg/s^2: 0.2 s
            servo.commit(begin + 0.5 + step.duration_s)
    for when, target in holds:
        angles, rates = servo.motion(np.array([when, when + 1.0]))
        assert np.allclose(angles / DEG, target, atol=1e-9) and not np.any(rates)
    for begin, axis, rate in plateaus:
        times = begin + np.linspace(0.0, 1.0, 11)
        rates = servo.motion(times)[1] / DEG
        assert np.allclose(rates[:, axis], rate) and np.allclose(np.delete(rates, axis, axis=1), 0.0)
    grid = np.arange(0.0, servo.horizon, 1e-3)
    rates = servo.motion(grid)[1] / DEG
    assert np.all(np.abs(rates) <= np.array(LIMITS["rate_dps"]) + 1e-9)
    assert np.all(np.abs(np.diff(rates, axis=0)) / 1e-3 <= np.array(LIMITS["accel_dps2"]) + 1e-6)
    # the truth follows the servo: over a plateau the IMU turns by the table's angle about the turning axis
    truth = Truth(Earth.from_degrees(32.0, 0.0), TableGeometry.from_config(static_config().turntable), servo.motion)
    begin, axis, rate = plateaus[0]  # outer axis, from the zero position: body z is the outer axis
    dtheta, _ = truth.increments(begin, begin + np.arange(1, 201) / RATE)
    earth_up = 7.2921151467e-5 * math.sin(32.0 * DEG)  # the earth rate's vertical part
    assert np.sum(dtheta[:, 2]) == pytest.approx((rate * DEG + earth_up) * 1.0, rel=1e-9)
