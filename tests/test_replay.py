"""Replay streamed from the recording: the emulated devices' reads recorded, replayed item by item as
``hil replay`` does, the same as the whole read, and a file cut short replayed up to the cut."""

from pathlib import Path

import pytest
import yaml

from emulators.reads import HOST_T0, emulated_reads
from hil.config import parse_config
from hil.recording.recorder import Recorder, read_recording
from hil.recording.replay import open_recording
from hil.trial.offline import replay_recording, run_replay
from hil.trial.outcome import TrialOutcome
from hil.trial.viewer_feed import ViewerOptions

ROOT = Path(__file__).resolve().parents[1]
DURATION = 20.0


@pytest.fixture(scope="module")
def config_text():
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["trial"]["duration_s"] = DURATION
    cfg["output"]["limits"] = {}
    return yaml.safe_dump(cfg)


@pytest.fixture(scope="module")
def recording(tmp_path_factory, config_text):
    path = tmp_path_factory.mktemp("replay") / "recording.mcap"
    recorder = Recorder(path, config_text, duration=DURATION, time_scale=1.0)
    for chunk in emulated_reads(parse_config(yaml.safe_load(config_text)), DURATION):
        recorder.write(chunk)
    recorder.close("completed")
    return path


def test_emulated_reads_are_every_frame_in_reads_of_a_tenth_of_a_second_in_host_time_order(config_text):
    reads = list(emulated_reads(parse_config(yaml.safe_load(config_text)), 2.0))
    times = [r.host_time for r in reads]
    assert times == sorted(times) and HOST_T0 < times[0] < times[-1] <= HOST_T0 + 2.1
    sizes = {stream: [len(r.data) for r in reads if r.stream == stream] for stream in ("imu", "table")}
    assert sum(sizes["imu"]) == 400 * 36 and sum(sizes["table"]) == 400 * 24
    assert set(sizes["imu"][:-1]) == {20 * 36} and set(sizes["table"][1:-1]) == {20 * 24}
    assert [r.stream for r in reads[:4]] == ["imu", "table", "imu", "table"]


def test_the_streamed_replay_is_the_replay_of_the_whole_read(recording):
    reader, cfg = open_recording(recording)
    with pytest.raises(RuntimeError):
        reader.truncated  # noqa: B018 - known once the items have been read
    streamed = replay_recording(reader, cfg)
    whole = replay_recording(read_recording(recording), cfg)
    assert not reader.truncated and reader.ended == "completed"
    counts = streamed.streams
    assert counts == whole.streams
    assert counts.imu_frames == counts.table_frames == counts.aligned == DURATION * 200
    assert counts.dropped == counts.corrupt == 0
    assert TrialOutcome.of(streamed, cfg, "", Path()).result == TrialOutcome.of(whole, cfg, "", Path()).result


def test_run_replay_ends_as_the_recording_says_after_reading_it(recording, tmp_path, capsys):
    outcome, _ = run_replay(recording, tmp_path / "out", ViewerOptions())
    assert outcome.ended == "completed" and outcome.result["trial"]["samples"] == DURATION * 200
    data = recording.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    cut, _ = run_replay(tmp_path / "cut.mcap", tmp_path / "cut", ViewerOptions())
    assert cut.ended == "early: the recording was cut short"
    assert "cut.mcap: the recording ends inside a record (cut short); replayed up to it" in capsys.readouterr().err
    assert 0.4 * DURATION * 200 < cut.result["trial"]["samples"] < 0.6 * DURATION * 200
