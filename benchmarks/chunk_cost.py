"""The processing chain's CPU cost per read, without threads or devices: what the live trial's main thread does.

A recorded trial's bytes (``hil run ... --out DIR`` writes DIR/recording.mcap) are cut into reads of
``--gather`` seconds of frames per stream, as the live readers hand them over, with host times on the
trial's clock, and fed through :class:`~hil.pipeline.processor.TrialProcessor` in arrival order.
Prints the CPU time per read and per IMU sample, the estimator updates, and the profile's top ten by own
time. ``--pause S`` sleeps S between reads, as the live processing thread idles between ticks: the same
work then costs more CPU (a thread woken from idle starts with cold caches), which is why the live
readers share one grid.

    .venv/bin/hil run --speed max --duration 60 --out /tmp/r60 --viewer none
    PYTHONPATH=. .venv/bin/python benchmarks/chunk_cost.py /tmp/r60 [--gather 0.01] [--batch N] [--repeat 3]
        [--pause 0.005]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

from drivers.codec import RawChunk
from drivers.kvh1750 import FRAME_SIZE as KVH_FRAME
from drivers.tts1 import FRAME_SIZE as TTS1_FRAME
from hil.pipeline.decoding import IMU, TABLE
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.progress import Finished
from hil.pipeline.settings import PipelineSettings
from hil.recording.replay import open_recording


def reads(items: list, imu_rate: float, table_rate: float, gather: float) -> list[RawChunk]:
    """Each stream's bytes in reads of ``gather`` s of frames, merged in arrival order."""
    out = []
    for stream, frame, rate in ((IMU, KVH_FRAME, imu_rate), (TABLE, TTS1_FRAME, table_rate)):
        data = b"".join(item.data for item in items if isinstance(item, RawChunk) and item.stream == stream)
        step = max(1, round(gather * rate)) * frame
        t0 = 1.0e9
        out += [RawChunk(stream, t0 + (i + step) / frame / rate, data[i:i + step]) for i in range(0, len(data), step)]
    return sorted(out, key=lambda chunk: chunk.host_time)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="run directory or recording of a KVH 1750 + TTS1 trial")
    parser.add_argument("--gather", type=float, default=0.01, help="s of frames a read holds (the live GATHER_S)")
    parser.add_argument("--batch", type=int, help="estimator.batch_samples (default: the recorded config's)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--pause", type=float, default=0.0, help="s of sleep between reads (CPU time is measured)")
    args = parser.parse_args()
    recording, cfg = open_recording(args.run)
    if cfg.imu.protocol != "kvh1750":
        parser.error(f"the recording's IMU speaks {cfg.imu.protocol}; this benchmark cuts kvh1750 frames")
    if args.batch is not None:
        cfg = cfg.model_copy(update={"estimator": cfg.estimator.model_copy(update={"batch_samples": args.batch})})
    with recording:
        chunks = reads(list(recording), cfg.imu_rate_hz, cfg.trial.rate_hz, args.gather)

    def run(pause: float = 0.0) -> Finished:
        processor = TrialProcessor(PipelineSettings.of(cfg), None, 1.0)
        for chunk in chunks:
            processor.feed(chunk)
            if pause:
                time.sleep(pause)
        return processor.finish()

    best = float("inf")
    for _ in range(args.repeat):
        start = time.thread_time()
        finished = run(args.pause)
        best = min(best, time.thread_time() - start)
    counts = finished.streams
    trial_s = finished.progress.trial_time
    print(f"imu {cfg.imu_rate_hz:g} Hz, table {cfg.trial.rate_hz:g} Hz, reads of {args.gather * 1e3:g} ms, "
          f"estimator.batch_samples {cfg.block_samples}, {args.pause * 1e3:g} ms between reads: {len(chunks)} reads, {counts.aligned} samples "
          f"aligned ({counts.dropped} dropped, {counts.corrupt} corrupt), {finished.progress.updates} estimator updates")
    print(f"best of {args.repeat}: {best:.3f} s of CPU for {trial_s:.1f} s of trial = {100 * best / trial_s:.2f} % of one core; "
          f"{1e6 * best / len(chunks):.0f} us per read, {1e6 * best / max(counts.aligned, 1):.1f} us per IMU sample")
    profile = cProfile.Profile()
    profile.runcall(run)
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(10)
    print("profile, top ten by own time:")
    print("\n".join(line for line in text.getvalue().splitlines() if line.strip()[:1].isdigit()))


if __name__ == "__main__":
    main()
