"""The emulated supply powering the emulated IMU, in process: ``hil emulate``'s supply (configs/emulated_power.yaml)
switched over SCPI between frames. Output off: the IMU sends nothing; on again: it boots, its counter from zero
(as a device's after a power cycle), its start-up flags raised, its self-heating from zero and a new turn-on bias drawn from
``imu.errors.turn_on_bias_ug``; the frames already sent are never changed."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
import pyvisa
import yaml

from drivers.kvh1750 import Kvh1750Codec
from drivers.scpi_supply import ScpiSupply, SupplySettings
from emulators.bench import Bench, device_streams
from emulators.clocks import TURN_ON_STREAM, turn_on_offset_ug
from emulators.scpi_supply import powering
from hil.config import parse_config

POWER = Path(__file__).resolve().parents[1] / "configs" / "emulated_power.yaml"
RATE_HZ = 200.0
START = 10  # the IMU's counter at power-on
SEED = 7


def config(**imu: object):
    """configs/emulated_power.yaml, the table still, the IMU without noise, counting from START."""
    cfg = yaml.safe_load(POWER.read_text())
    cfg["trial"].update(duration_s=4.0, seed=SEED)
    cfg["turntable"]["motion"] = {"kind": "static"}
    cfg["imu"]["errors"].update(accel_noise_ug=[0] * 3, gyro_noise_dph=[0] * 3)
    cfg["imu"].update(timing={"counter_start": START}, **imu)
    return parse_config(cfg)


class Powered:
    """The IMU's frame stream of ``cfg`` with ``hil emulate``'s supply feeding it, switched by the harness's driver."""

    def __init__(self, cfg) -> None:
        self.servo, streams = device_streams(cfg, 4.0)
        self.stream = streams["imu"]
        self.server = powering(cfg.environment.power, [self.stream.source.clock.supply], self.servo.lock)
        options = cfg.environment.power.options
        self.driver = ScpiSupply(self.server.resource, SupplySettings(options.voltage_v, options.current_limit_a,
                                                                      options.channel)).open()

    def frames(self, n: int) -> list:
        with self.servo.lock:
            return [self.stream.pop(self.servo) for _ in range(n)]

    def close(self) -> None:
        self.driver.close()
        self.server.close()


@pytest.fixture
def powered():
    rig = Powered(config(faults={"start_up_s": 0.05}))
    yield rig
    rig.close()


def decoded(frames: list) -> list:
    codec = Kvh1750Codec(RATE_HZ)
    return [codec.decode(e.payload) for e in frames]


def test_output_off_silences_the_imu_and_on_boots_it_from_counter_zero_with_its_start_up_flags(powered):
    before = powered.frames(100)  # ticks 1..100
    powered.driver.output(False)
    off = powered.frames(50)  # ticks 101..150
    powered.driver.output(True)
    after = powered.frames(100)  # ticks 151..250
    assert all(e.powered for e in before) and not any(e.powered for e in off) and all(e.powered for e in after)
    assert [f.sequence for f in decoded(before)][:3] == [(START + k) % 128 for k in range(1, 4)]  # from its own start
    assert [f.sequence for f in decoded(after)] == [k % 128 for k in range(100)]
    assert [e.invalid for e in after] == [True] * 10 + [False] * 90  # start_up_s 0.05 s at 200 Hz
    assert [e.invalid for e in before] == [True] * 9 + [False] * 91  # the trial's start: ticks 1..9
    assert decoded(after)[0].status == Kvh1750Codec(RATE_HZ).flagged_status(Kvh1750Codec.start_up_flags)
    untouched = Powered(config(faults={"start_up_s": 0.05}))
    try:
        assert [e.payload for e in untouched.frames(100)] == [e.payload for e in before]
    finally:
        untouched.close()


def test_each_power_on_draws_a_new_turn_on_bias_from_the_configured_spread(powered):
    def accel_ug(frames: list) -> np.ndarray:
        return np.mean([f.accel for f in decoded(frames[20:])], axis=0) * 1e6  # g -> ug

    levels = [accel_ug(powered.frames(100))]
    for _ in range(2):
        powered.driver.output(False)
        powered.frames(20)
        powered.driver.output(True)
        levels.append(accel_ug(powered.frames(100)))
    for n in (1, 2):
        drawn = turn_on_offset_ug([40.0] * 3, (SEED, TURN_ON_STREAM, n))
        assert np.allclose(levels[n] - levels[0], drawn, atol=0.5), (n, levels[n] - levels[0], drawn)
    assert np.all(np.abs(levels[2] - levels[1]) > 1.0)
    assert powered.server.state.power_ons == 3  # powered from the start, then twice


def test_the_self_heating_starts_again_at_each_power_on():
    """The KVH 1750 reports whole deg C: the sensor at 25 deg C, 10 deg C of self-heating with a 1 s warm-up."""
    thermal = {"reference_c": 25.0, "self_heating_c": 10.0, "warmup_tau_s": 1.0, "case_tau_s": 600.0}
    rig = Powered(config(errors={**yaml.safe_load(POWER.read_text())["imu"]["errors"], "thermal": thermal}))
    try:
        warm = decoded(rig.frames(400))[-1].temperature  # 2 s after power-on: 25 + 10 (1 - exp(-2)) = 33.6
        rig.driver.output(False)
        rig.frames(10)
        rig.driver.output(True)
        cold = decoded(rig.frames(1))[0].temperature  # at power-on
    finally:
        rig.close()
    assert (warm, cold) == (34, 25)


def test_hil_emulate_names_its_supply_in_the_ports_and_a_visa_client_sees_the_imu_powered():
    bench = Bench(config(), 1.0, None, threading.Event(), wait_readers=False)
    try:
        resource = bench.names()["power"]
        client = pyvisa.ResourceManager("@py").open_resource(resource, read_termination="\n",
                                                            write_termination="\n")
        assert client.query("OUTP?") == "1" and float(client.query("MEAS:CURR?")) == pytest.approx(0.35)
        assert float(client.query("MEAS:VOLT?")) == 5.0
        client.write("OUTP OFF")
        assert client.query("OUTP?") == "0" and not bench.streams["imu"].source.clock.supply.on
        client.close()
    finally:
        bench.close()
