"""The devices' own health flags: each codec reads its device's status into per-sample validity (golden frames
from the devices' public documents and drivers), a sample the device flags is never estimated but counted in all
and by flag, judged by ``output.limits.invalid_max``, and ``hil decode`` says which frames were flagged."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import yaml
from test_stim300 import TEMPERATURE_A5
from tests.helpers import make_config

from drivers.codec import RawChunk, raised_flags
from drivers.kvh1750 import Kvh1750Codec
from drivers.registry import IMU_CODECS
from drivers.stim300 import Stim300Codec
from drivers.xsens import XsensCodec
from emulators.simulation import Simulation
from hil.config import ReportLimits
from hil.outputs.measurements import FAIL, PASS, measurements
from hil.pipeline.decoding import IMU, TABLE
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.settings import PipelineSettings
from hil.samples import ImuSample, TableSample

# TRECVT/ros_kvh1750 test/utest.cpp, case "early": a KVH 1750 frame at power-up, status 0x70 (accelerometers
# valid, the three gyros not yet), sequence 31, 29 deg C; and case "basic", status 0x77 (all valid), sequence 104.
KVH_POWER_UP = bytes.fromhex("FE81FF55 3B041F78 B9B96613 BA234B38 BB7C0410 B8DEF480 3F7F4B7B 70 1F 001D F12FB6EE")
KVH_VALID = bytes.fromhex("FE81FF55 B3D0BBE7 32193EF4 30AC19A5 BA8F78D6 3A290594 3F7ECBD4 77 68 001D ADC5F651")
# MTData2 by the Xsens MT Low-Level Communication Protocol: PacketCounter 5, StatusWord 0x00000801 (bit 0
# self-test passed, bit 11 the gyro x clipping), DeltaQ (1, 0, 0, 0), DeltaV (0, 0, 0.0098154) m/s; checksum 0x6D.
XSENS_GYRO_X_CLIPPING = bytes.fromhex("FAFF362E 1020020005 E0200400000801 8030103F800000000000000000000000000000"
                                      "40100C00000000000000003C20D0E5 6D")


def _flags(codec, data: bytes) -> list[list[str]]:
    """The names of the flags each frame of ``data`` raises."""
    frames = codec.framer(None).feed_chunk(RawChunk("imu", 0.0, data))
    raised = raised_flags(codec.health_flags, codec.status_words(frames.rows))
    return [[flag.name for flag, hit in zip(codec.health_flags, row) if hit] for row in raised]


def test_the_kvh_power_up_frame_flags_its_three_gyros_and_a_running_one_nothing():
    codec = Kvh1750Codec(1000)
    record = codec.decode(KVH_POWER_UP)
    assert (record.status, record.sequence, record.temperature) == (0x70, 31, 29)
    assert _flags(codec, KVH_POWER_UP + KVH_VALID) == [["gyro_x_invalid", "gyro_y_invalid", "gyro_z_invalid"], []]


def test_an_xsens_status_word_flags_clipping_and_a_failed_self_test_and_real_captures_nothing():
    codec = XsensCodec(100)
    assert codec.decode(XSENS_GYRO_X_CLIPPING).status_word == 0x801
    assert _flags(codec, XSENS_GYRO_X_CLIPPING) == [["clipping_gyro_x"]]
    no_self_test = codec.encode(codec.from_sample(ImuSample(6, (0.0,) * 3, (0.0, 0.0, 0.01), status=0x0)))
    assert _flags(codec, no_self_test) == [["self_test_failed"]]
    assert _flags(codec, codec.encode(codec.from_sample(ImuSample(7, (0.0,) * 3, (0.0, 0.0, 0.01))))) == [[]]


def test_a_stim300_gyro_status_in_start_up_flags_the_sample():
    codec = Stim300Codec(2000, datagram=0xA5, gyro_output="rate", accel_output="acceleration", accel_range_g=10)
    assert _flags(codec, TEMPERATURE_A5) == [["gyro_start_up"]]


@pytest.mark.parametrize("protocol", ["kvh1750", "xsens-mtdata2", "stim300", "can-dbc"])
def test_a_healthy_device_raises_no_flag_and_each_flag_names_one_bit(protocol):
    cls = IMU_CODECS.get(protocol)
    assert cls.health_flags and not raised_flags(cls.health_flags, np.array([cls.healthy_status])).any()
    masks = [flag.mask for flag in cls.health_flags]
    assert all(bin(m).count("1") == 1 for m in masks) and len(set(masks)) == len(masks)


def test_hil_decode_counts_the_flagged_frames_and_marks_them_in_the_csv(tmp_path, capsys):
    from hil.cli import main

    (tmp_path / "cap.bin").write_bytes(KVH_POWER_UP + KVH_VALID)
    assert main(["decode", "kvh1750", str(tmp_path / "cap.bin"), "--out", str(tmp_path / "out.csv")]) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["invalid"] == 1
    rows = list(csv.DictReader((tmp_path / "out.csv").open()))
    assert [(row["status"], row["valid"]) for row in rows] == [("0x70", "0"), ("0x77", "1")]


RATE = 100.0
CFG = make_config(duration=20.0, rate=RATE)
CODECS = PipelineSettings.of(CFG).codecs()
BATCH = next(Simulation.from_config(CFG).batches(chunk=10**6))
POWER_UP = 0x70  # the gyros flagged invalid


def _processed(status_of, garbage: float = 0.0, duration: float = 20.0, cfg=CFG):
    """A processor fed a 20 s swing's KVH and table frames in reads of 0.5 s, the IMU's status per sample
    ``status_of(k)``; a flagged sample's gyro reads ``garbage`` rad more than the truth."""
    imu, table = CODECS[IMU], CODECS[TABLE]
    processor = TrialProcessor(PipelineSettings.of(cfg), duration, None)
    n = len(BATCH)
    progress = None
    for start in range(0, n, 50):
        ks = range(start, min(start + 50, n))
        imu_bytes = b"".join(imu.encode(imu.from_sample(ImuSample(
            k + 1, tuple(BATCH.dtheta[k] + (garbage if status_of(k) != 0x77 else 0.0)), tuple(BATCH.dv[k]),
            status=status_of(k)))) for k in ks)
        table_bytes = b"".join(table.encode(table.from_sample(TableSample(k + 1, tuple(BATCH.angles[k])))) for k in ks)
        processor.feed(RawChunk("table", start / RATE, table_bytes))
        progress = processor.feed(RawChunk("imu", start / RATE, imu_bytes))
        if progress.stalled:
            return processor, progress
    processor.finish()
    return processor, progress


def test_a_flagged_sample_is_never_estimated_and_is_counted_by_flag_not_as_lost():
    flagged = {k for k in range(len(BATCH)) if k % 97 == 13}
    processor, _ = _processed(lambda k: POWER_UP if k in flagged else 0x77, garbage=0.5)
    finished = processor.finished()
    streams = finished.streams.as_dict()
    assert streams["imu_invalid"] == len(flagged)
    assert streams["imu_invalid_by_flag"] == {f"gyro_{axis}_invalid": len(flagged) for axis in "xyz"}
    assert (streams["aligner_imu_filled"], streams["imu_gated"], streams["imu_implausible"]) == (0, 0, 0)
    assert finished.estimator.solution().samples == streams["aligned"] - len(flagged)
    assert np.abs(finished.estimator.solution().full.bias).max() < 1e-5 * 9.8  # 10 ug: half a rad never reached it


def test_every_sample_flagged_stalls_the_trial_naming_the_flags():
    _, progress = _processed(lambda k: POWER_UP, duration=20.0)
    assert progress.stalled is not None and progress.trial_time < 10.0
    assert "gyro_x_invalid, gyro_y_invalid, gyro_z_invalid" in progress.stalled, progress.stalled


def test_flagged_samples_never_end_a_trial_that_expects_them():
    """hil ratetest's live form: a step beyond the gyro's range flags every sample for longer than the stall."""
    cfg = CFG.model_copy(update={"estimator": CFG.estimator.model_copy(update={"flags_end_trial": False})})
    processor, progress = _processed(lambda k: POWER_UP if k < 1500 else 0x77, cfg=cfg)  # 15 s flagged
    assert progress.stalled is None
    assert processor.finished().streams.as_dict()["imu_invalid"] == 1500


@pytest.mark.parametrize(("invalid", "limits", "outcome"), [(10, {}, FAIL), (2, {}, PASS),
                                                             (10, {"invalid_max": 0.05}, PASS)])
def test_the_fraction_flagged_is_judged_against_invalid_max_of_one_in_a_thousand_by_default(invalid, limits, outcome):
    streams = {"aligner_aligned": 2000, "aligner_imu_bridged": 0, "aligner_imu_filled": 0, "imu_gated": 0,
               "aligner_without_angles": 0, "imu_invalid": invalid, "imu_invalid_by_flag": {"gyro_x_invalid": invalid}}
    judged = {m.name: m for m in measurements({"streams": streams}, ReportLimits(**limits))}
    assert (judged["imu_invalid_fraction"].value, judged["imu_invalid_fraction"].outcome) == (invalid / 2000, outcome)
    assert judged["imu_invalid_gyro_x_invalid"].value == invalid


def yaml_config(tmp_path, faults: dict, limits: dict | None = None):
    """configs/emulated_swing.yaml with the IMU's ``faults`` and ``output.limits`` (default: the defaults)."""
    from test_emulator_counters import SWING

    cfg = yaml.safe_load(SWING.read_text())
    cfg["imu"]["faults"] = faults
    cfg["output"] = {"limits": limits or {}}
    path = tmp_path / "flagged.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_the_emulated_imu_flags_its_gyros_while_it_starts_and_inside_the_invalid_window():
    from test_emulator_counters import POWER_CYCLE, config, emitted

    cfg = config({"rate_hz": 200.0, "faults": {"start_up_s": 0.25, "invalid_at_s": 0.5, "invalid_s": 0.1}})
    statuses = [Kvh1750Codec(200.0).decode(e.payload).status for e in emitted(cfg, "imu", 1.0)]
    # latches at k / 200 + 50 us: ticks 1-49 start up, 100-119 inside the window (0.5 s <= t < 0.6 s)
    assert [k + 1 for k, s in enumerate(statuses) if s == POWER_UP] == [*range(1, 50), *range(100, 120)]
    assert {s for s in statuses if s != POWER_UP} == {0x77}
    cycled = config({"rate_hz": 200.0, "faults": {**POWER_CYCLE, "start_up_s": 0.1}})
    flagged = [e.tick for e in emitted(cycled, "imu", 1.0) if e.powered and e.invalid]
    assert flagged == [*range(1, 20), *range(150, 170)]  # again after the power cycle's 0.5 to 0.75 s


def test_the_emulator_counts_the_flagged_frames_it_wrote_and_a_run_judges_them(tmp_path):
    from test_faults import capture

    from hil.cli import main
    from hil.config import parse_config

    doc = yaml_config(tmp_path, {"invalid_rate": 0.02})
    stats, out = capture(parse_config(yaml.safe_load(doc.read_text())), duration=2.0)
    frames = Kvh1750Codec(200.0).framer().feed_bytes(bytes(out["imu"]))
    assert stats.devices["imu"].faults["invalid"] == int(np.count_nonzero(frames.rows["status"] == POWER_UP)) > 0

    code = main(["run", str(doc), "--speed", "max", "--duration", "10", "--out", str(tmp_path / "run"),
                 "--viewer", "none", "--no-figures", "--quiet"])
    streams = json.loads((tmp_path / "run" / "result.json").read_text())["streams"]
    failed = [line for line in (tmp_path / "run" / "junit.xml").read_text().splitlines() if "<failure" in line]
    assert code == 3 and 0.01 < streams["imu_invalid"] / streams["aligned"] < 0.03, streams
    assert len(failed) == 1 and "imu_invalid_fraction" in failed[0], failed
