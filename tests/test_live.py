"""``hil run`` end to end on the emulated devices, its bit-exact replay, and a kill -9 mid-trial."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hil.cli import main
from hil.config import load_config
from hil.recording.recorder import Recorder, read_recording
from hil.recording.replay import open_recording
from hil.trial.latency_stats import LatencyStats
from hil.trial.live import LiveSettings, LiveTrial, TrialAborted
from hil.trial.rig import data_links
from hil.vocabulary import DevicePorts
from hil.trial.offline import replay_recording
from tests.helpers import processed

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    code = main(["run", "--duration", "120", "--speed", "max", "--quiet", "--no-figures", "--out", str(out)])
    assert code == 0
    return out


def test_run_estimates_the_bias_within_its_sigma(live_run):
    result = json.loads((live_run / "result.json").read_text())
    assert result["trial"]["samples"] == 24000
    streams = result["streams"]
    assert streams["imu_frames"] == streams["table_frames"] == streams["aligned"] == 24000
    assert streams["dropped"] == streams["corrupt"] == streams["imu_outages"] == 0
    assert abs(streams["sync_offset_ms"]) < 0.01
    est = result["estimate"]
    assert est["observable"] and est["gram_rank"] == 12
    error = np.subtract(est["accel_bias_ug"], result["truth"]["accel_bias_ug"])
    assert np.all(np.abs(error) < 4 * np.array(est["accel_bias_sigma_ug"]))
    assert (live_run / "recording.mcap").stat().st_size > 24000 * 2 * 30
    assert json.loads((live_run / "emulator.json").read_text())["pulses"] == 24000
    assert "pulses" in (live_run / "emulator.log").read_text()  # the emulator's stderr, not the console


def test_replay_reproduces_the_result_exactly(live_run, tmp_path):
    assert main(["replay", str(live_run), "--out", str(tmp_path), "--no-figures"]) == 0
    assert processed(tmp_path) == processed(live_run)
    assert (tmp_path / "series.csv").read_text() == (live_run / "series.csv").read_text()


def test_the_emulated_devices_reads_recorded_without_ports_replay_to_the_live_result(live_run, tmp_path):
    from emulators.reads import emulated_reads

    recording, cfg = open_recording(live_run)
    recording.close()
    duration = float(recording.metadata["duration_s"])
    # unpaced, as the live run (--speed max) was: whole blocks decide the updates, so any reads of its frames give its result
    recorder = Recorder(tmp_path / "reads.mcap", recording.metadata["config"], duration=duration, time_scale=None)
    for chunk in emulated_reads(cfg, duration):
        recorder.write(chunk)
    recorder.close("completed")
    assert main(["replay", str(tmp_path / "reads.mcap"), "--out", str(tmp_path / "out"), "--no-figures"]) == 0
    live, again = (processed(d) for d in (live_run, tmp_path / "out"))
    # the pairing is the same; which read brought the data that confirmed it is the reads' own
    assert live["streams"]["sync"].pop("confirmed_at_s") is not None and again["streams"]["sync"].pop("confirmed_at_s")
    assert again == live


def test_replay_of_a_trial_that_fails_its_limits_exits_3(live_run, tmp_path):
    import xml.etree.ElementTree as ET

    import yaml

    rec = read_recording(live_run / "recording.mcap")
    cfg = yaml.safe_load(rec.metadata["config"])
    cfg["output"]["limits"] = {"bias_sigma_ug_max": 1e-6}
    recorder = Recorder(tmp_path / "strict.mcap", yaml.safe_dump(cfg), duration=float(rec.metadata["duration_s"]),
                        time_scale=None)  # as recorded at --speed max
    for item in rec.items:
        recorder.write(item)
    recorder.close()
    assert main(["replay", str(tmp_path / "strict.mcap"), "--out", str(tmp_path / "out"), "--no-figures"]) == 3
    suite = ET.parse(tmp_path / "out" / "junit.xml").getroot().find("testsuite")
    # the three sigmas fail; the judged data (missing, gated, flagged invalid, without angles, sync offset) pass
    assert (suite.get("tests"), suite.get("failures")) == ("8", "3")


def test_kill_minus_9_keeps_the_recording_up_to_a_second_before(tmp_path):
    cmd = [sys.executable, "-m", "hil.cli", "run", "--duration", "60", "--quiet", "--no-figures",
           "--out", str(tmp_path)]
    proc = subprocess.Popen(cmd, cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    recording = tmp_path / "recording.mcap"
    try:
        deadline = time.monotonic() + 30
        while not (recording.exists() and recording.stat().st_size > 50_000):
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.1)
        time.sleep(1.5)
        proc.send_signal(signal.SIGKILL)
        killed_at = time.time()
        proc.wait()
    finally:
        proc.kill()
    # the emulator, in its own session, ends with the harness: it removes its ports file on the way out
    deadline = time.monotonic() + 10
    while (tmp_path / "ports.json").exists():
        assert time.monotonic() < deadline, "the emulator outlived the killed harness"
        time.sleep(0.05)
    rec = read_recording(recording)
    assert rec.truncated or rec.items  # cut anywhere: still readable
    first = rec.items[0].host_time
    finished = replay_recording(*open_recording(recording))
    # everything the devices sent up to 1 s before the kill is there and replays
    assert finished.progress.trial_time >= killed_at - first - 1.0 - 0.1
    assert finished.progress.health["imu"]["corrupt"] == 0


FAULT_RUN_S = 200.0  # the faults' counts and the bias kept need no 10 minutes; the unplug is at 100 s


def _run_config(tmp_path, name, limits=None, **imu_and_table):
    import yaml

    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["imu"]["protocol"] = "xsens-mtdata2"  # a 16-bit packet counter: a 2 s outage is sized at any speed
    cfg["output"]["limits"].update(limits or {})
    for section, faults in imu_and_table.items():
        cfg[section]["faults"] = faults
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / name
    assert main(["run", str(path), "--duration", str(FAULT_RUN_S), "--speed", "max", "--quiet", "--no-figures",
                 "--viewer", "none", "--out", str(out)]) == 0
    return json.loads((out / "result.json").read_text()), out


@pytest.mark.slow
def test_fault_run_completes_counts_every_fault_and_keeps_the_bias(tmp_path):
    faults = {"drop_rate": 0.01, "corrupt_byte_rate": 0.001, "jitter_ms": 2.0}
    clean, _ = _run_config(tmp_path, "clean")
    # 1 % of the frames dropped, 5 % hit by a bit error, 2 s unplugged: the default 0.1 % limits would fail it
    faulty, out = _run_config(tmp_path, "faulty", {"missing_max": 0.1, "gated_max": 0.01, "without_angles_max": 0.01},
                              imu={**faults, "unplug_at_s": 100.0, "unplug_s": 2.0}, turntable=faults)
    assert faulty["trial"]["duration_s"] == pytest.approx(FAULT_RUN_S)
    s = faulty["streams"]
    assert s["imu_outages"] == 1
    # every frame lost to a drop, a bit error or the unplug is counted as missing, bar the last few
    # (no later frame reveals them) and the damaged frames Xsens' 8-bit checksum lets through (~0.4 %),
    # which the plausibility checks catch when their damage matters
    injected = json.loads((out / "emulator.json").read_text())["devices"]
    for stream, device in (("imu", "imu"), ("table", "turntable_data")):
        f = injected[device]["faults"]
        lost = f["dropped"] + f["corrupted"] + f["truncated"] + f["unplugged"]
        assert lost - 0.005 * f["corrupted"] - 5 <= s[f"{stream}_missing"] <= lost
    assert injected["imu"]["faults"]["unplugs"] == 1
    assert s["corrupt"] > 1000 and s["skipped_bytes"] > 0
    assert s["aligner_imu_filled"] > 0 and s["aligner_imu_bridged"] >= 400 and s["bridged_without_table"] == 0
    # the ~8 % of the samples the faults cost move the bias by a fraction of its sigma (~0.3), never by 0.6
    moved = np.subtract(faulty["estimate"]["accel_bias_ug"], clean["estimate"]["accel_bias_ug"])
    assert np.all(np.abs(moved) < 0.6 * np.array(faulty["estimate"]["accel_bias_sigma_ug"])), moved
    again = tmp_path / "again"
    assert main(["replay", str(out), "--out", str(again), "--no-figures", "--viewer", "none"]) == 0
    faulty.pop("record")
    assert processed(again) == faulty


def test_age_counts_from_the_chunk_that_completed_the_oldest_sample_taken():
    """Blocks of 3 from chunks of 4 samples: the sample left over waits for the next chunk, and the age of
    the block it opens counts from the chunk that brought it, not from the chunk that closed the block."""
    stats = LatencyStats()
    now = time.time()
    stats.fed(now - 0.040, 4)  # samples 1-4; the estimator takes 1-3, 4 waits
    stats.updated(1)
    stats.fed(now - 0.035, 4)  # a chunk that completes no sample is not kept
    stats.fed(now - 0.020, 8)  # samples 5-8: blocks 4-6, then 7-8 wait
    stats.updated(2)
    (age_p50, _), (latency_p50, _) = stats.age.percentiles_ms([50, 99]), stats.latency.percentiles_ms([50, 99])
    assert age_p50 >= 40.0 and 20.0 <= latency_p50 < 40.0  # both blocks' oldest sample came at -40 ms
    assert [done for _, done in stats._arrivals] == [8]  # kept until samples 7 and 8 are taken


@pytest.mark.parametrize(("imu_rate", "batch", "period"), [
    (200.0, None, 0.05),  # the default block, 50 ms
    (1000.0, None, 0.05),  # 50 frames
    (2000.0, None, 0.025),  # 50 frames at most: half a block
    (200.0, 3, 0.02),  # a block shorter than the shortest read period
    (200.0, 20, 0.1),
])
def test_the_read_period_is_one_block_within_its_bounds(imu_rate, batch, period):
    cfg = load_config("configs/emulated_swing.yaml")
    cfg = cfg.model_copy(update={"imu": cfg.imu.model_copy(update={"rate_hz": imu_rate}),
                                 "estimator": cfg.estimator.model_copy(update={"batch_samples": batch})})
    assert cfg.read_s == pytest.approx(period)


def test_a_live_trial_rides_out_an_outage_shorter_than_its_limit(tmp_path):
    """``output.outage_limit_s`` is how long every device may be silent (the readers reconnecting) before
    the trial ends early."""
    cfg = load_config("configs/lab_swing.yaml")
    unasked = cfg.imu.model_copy(update={"options": {**cfg.imu.options, "check_config": False}})  # no port is opened
    cfg = cfg.model_copy(update={"output": cfg.output.model_copy(update={"outage_limit_s": 3.0}), "imu": unasked})
    trial = LiveTrial(LiveSettings.of(cfg), "", tmp_path, None, data_links(cfg, DevicePorts("/dev/imu", "/dev/table")))
    try:
        trial.fanout.last_arrival = 100.0  # the last data, monotonic s
        trial._check_alive(102.9, started=90.0)  # an outage of 2.9 s: the trial goes on
        with pytest.raises(TrialAborted, match=r"^no data from any device for 3 s \(output.outage_limit_s\)$"):
            trial._check_alive(103.1, started=90.0)
        trial.readers[0].down = "imu: /dev/pts/7 is now another program's pseudo-terminal; not reopening"
        with pytest.raises(TrialAborted, match=r"\(output.outage_limit_s\): imu: /dev/pts/7 is now another program's"):
            trial._check_alive(103.1, started=90.0)  # why a port stays down
    finally:
        trial.recorder.close()
    assert load_config("configs/emulated_swing.yaml").output.outage_limit_s == 10.0  # the default
