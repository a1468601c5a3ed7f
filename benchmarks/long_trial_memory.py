"""A long trial in flat memory: `hil simulate` or `hil replay` of the default swing for 24 h at 200 Hz (17.3 M samples).

Simulate (the default) runs what `hil simulate` runs (the emulator's batches, computed ahead by a child
process, into the trial processor, then every output, figures and report included) in this process.

`--replay` first writes the trial's recording with the harness's own Recorder, in its MCAP format: the
emulated devices' wire frames (KVH 1750 and tts1, from `emulators.reads`) in reads of 0.1 s per stream,
interleaved in time as two device readers hand them over, host times on a real-time clock (so the
recording replays at time_scale 1), and prints how long that took and the file's size. Then it replays
the file in this process through what `hil replay` runs (the streamed reader into `replay_recording`,
then every output). `--recording PATH` keeps the file there, or replays PATH as it is if it exists.

Both print the resident memory and the wall time at every hour of trial time (every quarter of the
trial when it is shorter than 4 h), the peak resident memory (simulate: the emulator's process's too) and
the samples per second:

    .venv/bin/python benchmarks/long_trial_memory.py [--hours 24] [--rate 200] [--config configs/emulated_swing.yaml]
    .venv/bin/python benchmarks/long_trial_memory.py --replay [--hours 24] [--recording PATH]
    .venv/bin/python benchmarks/long_trial_memory.py --replay --hours 0.5   # a quick check
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import yaml
from live_harness import rss_mib

from drivers.codec import RawChunk, StreamEvent
from emulators.reads import emulated_reads
from emulators.simulation_process import SimulationProcess
from hil.config import Config, parse_config
from hil.outputs.result import COMPLETED
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.progress import Finished
from hil.pipeline.settings import PipelineSettings
from hil.recording.recorder import Recorder, RecordingReader
from hil.recording.replay import open_recording
from hil.trial.offline import how_it_ended, replay_recording
from hil.trial.outcome import TrialOutcome, emulated_truth
from hil.units import HOUR

MAX_BACKLOG = 2000  # reads queued for the recorder's writer thread before the writing waits for it
MIB = 1024 * 1024


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


class Rows:
    """The table of trial time, resident memory and wall time, a row at every ``every`` s of trial time."""

    def __init__(self, every: float) -> None:
        self.every = every
        self.wall0 = time.monotonic()
        self.next = 0.0
        print(f"{'trial time (h)':>15} {'RSS (MiB)':>10} {'wall (s)':>9}", flush=True)

    def at(self, t: float) -> None:
        """Trial time ``t`` (s) reached: a row if it passes the next mark."""
        if t >= self.next:
            self.row(f"{t / HOUR:15.2f}")
            self.next = (t // self.every + 1) * self.every

    def row(self, label: str, note: str = "") -> None:
        print(f"{label:>15} {rss_mib():10.1f} {self.wall():9.1f}{note}", flush=True)

    def wall(self) -> float:
        return time.monotonic() - self.wall0


def trial_config(path: str, hours: float, rate: float) -> tuple[Config, str]:
    """The config of ``path`` lengthened to ``hours`` with the IMU and the table at ``rate`` Hz, and its YAML
    (what the recording stores)."""
    data = yaml.safe_load(Path(path).read_text())
    data["trial"].update(duration_s=hours * HOUR, rate_hz=rate)
    data["imu"].pop("rate_hz", None)
    return parse_config(data, path), yaml.safe_dump(data, sort_keys=False)


def simulate(cfg: Config, config_text: str, every: float) -> None:
    rows = Rows(every)
    processor = TrialProcessor(PipelineSettings.of(cfg))
    with SimulationProcess() as simulation:
        for batch in simulation.batches(cfg):  # as hil simulate: computed by a child process, ahead
            processor.feed_batch(batch)
            rows.at(float(batch.t[-1]))
    child_mib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # the emulator's, reaped by now
    finished = processor.finished()
    samples = finished.streams.aligned
    outputs(finished, cfg, config_text, COMPLETED, rows)
    print(f"peak RSS {peak_mib():.1f} MiB (the emulator's process: {child_mib:.1f} MiB), "
          f"{samples / rows.wall():,.0f} samples/s over the whole run")


def write_recording(cfg: Config, config_text: str, path: Path, every: float) -> None:
    """The emulated devices' reads of the whole trial into ``path`` through the Recorder, at most
    ``MAX_BACKLOG`` reads queued at a time."""
    duration = cfg.trial.duration_s
    print(f"writing {path}: the emulated devices' reads of 0.1 s per stream, through the Recorder")
    rows = Rows(every)
    recorder = Recorder(path, config_text, duration=duration, time_scale=1.0)
    first = None
    for chunk in emulated_reads(cfg, duration):
        recorder.write(chunk)
        while recorder.backlog > MAX_BACKLOG:
            time.sleep(0.001)
        first = chunk.host_time if first is None else first
        rows.at(chunk.host_time - first)
    recorder.close(COMPLETED)
    size = path.stat().st_size
    rows.row("written", f"   {recorder.messages:,} reads, {size / MIB:,.1f} MiB ({size / 1e9:.2f} GB), "
                        f"{2 * round(duration * cfg.imu_rate_hz) / rows.wall():,.0f} frames/s")
    print(f"writing: {rows.wall():.1f} s, peak RSS so far {peak_mib():.1f} MiB")


class Hourly:
    """A reader's items as they are read, with a row at each mark of trial time (from the host times)."""

    def __init__(self, reader: RecordingReader, rows: Rows) -> None:
        self.reader, self.rows, self.metadata = reader, rows, reader.metadata

    def __iter__(self) -> Iterator[RawChunk | StreamEvent]:
        first = None
        for item in self.reader:
            first = item.host_time if first is None else first
            self.rows.at(item.host_time - first)
            yield item


def replay(path: Path, every: float) -> None:
    size = path.stat().st_size
    print(f"replaying {path} ({size / MIB:,.1f} MiB) as hil replay does")
    reader, cfg = open_recording(path)
    rows = Rows(every)
    with reader:
        finished = replay_recording(Hourly(reader, rows), cfg)  # type: ignore[arg-type]  # the reader, watched
    ended = how_it_ended(reader)
    rows.row("replayed", f"   {reader.metadata['duration_s']} s recorded, truncated {reader.truncated}, "
                         f"ended {reader.ended!r}")
    samples = finished.streams.aligned
    replay_s = rows.wall()
    outputs(finished, cfg, reader.metadata["config"], ended, rows)
    print(f"peak RSS {peak_mib():.1f} MiB, {samples:,} samples replayed at {samples / replay_s:,.0f} samples/s "
          f"({size / MIB / replay_s:.1f} MiB/s of recording), {samples / rows.wall():,.0f} samples/s with the outputs")


def outputs(finished: Finished, cfg: Config, config_text: str, ended: str, rows: Rows) -> None:
    """Every output of the trial, written to a temporary directory."""
    with tempfile.TemporaryDirectory() as tmp:
        outcome = TrialOutcome.of(finished, cfg, config_text, Path(tmp), ended, emulated_truth(cfg))
        verdict = outcome.write().verdict
    rows.row("outputs written", f"   ({verdict})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=24.0)
    parser.add_argument("--rate", type=float, default=200.0, help="IMU and table rate (Hz)")
    parser.add_argument("--config", default="configs/emulated_swing.yaml")
    parser.add_argument("--replay", action="store_true", help="write the trial's recording, then replay it")
    parser.add_argument("--recording", type=Path, help="--replay: keep the recording here (replay it if it exists)")
    args = parser.parse_args()
    cfg, config_text = trial_config(args.config, args.hours, args.rate)
    every = min(HOUR, args.hours * HOUR / 4)
    samples = round(cfg.trial.duration_s * cfg.imu_rate_hz)
    print(f"{samples:,} samples ({args.hours:g} h at {args.rate:g} Hz), {args.config}, "
          f"{'hil replay' if args.replay else 'hil simulate'}")
    if not args.replay:
        simulate(cfg, config_text, every)
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = args.recording or Path(tmp) / "recording.mcap"
        if not path.exists():
            write_recording(cfg, config_text, path, every)
        replay(path, every)


if __name__ == "__main__":
    main()
