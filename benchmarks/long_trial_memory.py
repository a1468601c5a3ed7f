"""A long trial in flat memory: `hil simulate` of the default swing for 24 h at 200 Hz (17.3 M samples).

Runs what `hil simulate` runs (the emulator's batches into the trial processor, then every output,
figures and report included) in this process and prints the resident memory at every hour of trial
time, the peak, and the time taken:

    .venv/bin/python benchmarks/long_trial_memory.py [--hours 24] [--rate 200] [--config configs/emulated_swing.yaml]
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

from live_harness import rss_mib

from emulators.simulation import Simulation
from hil.config import load_config
from hil.pipeline.processor import TrialProcessor
from hil.trial.outcome import TrialOutcome, emulated_truth
from hil.units import HOUR


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=24.0)
    parser.add_argument("--rate", type=float, default=200.0, help="IMU and table rate (Hz)")
    parser.add_argument("--config", default="configs/emulated_swing.yaml")
    args = parser.parse_args()
    cfg = load_config(args.config)
    trial = cfg.trial.model_copy(update={"duration_s": args.hours * HOUR, "rate_hz": args.rate})
    cfg = cfg.model_copy(update={"trial": trial, "imu": cfg.imu.model_copy(update={"rate_hz": None})})
    sim = Simulation.from_config(cfg)
    print(f"{sim.samples:,} samples ({args.hours:g} h at {args.rate:g} Hz), {args.config}")
    print(f"{'trial time (h)':>15} {'RSS (MiB)':>10} {'wall (s)':>9}")
    wall0 = time.monotonic()
    processor = TrialProcessor(cfg)
    next_hour = 0.0
    for batch in sim.batches():
        processor.feed_batch(batch)
        if batch.t[-1] >= next_hour:
            print(f"{batch.t[-1] / HOUR:15.1f} {rss_mib():10.1f} {time.monotonic() - wall0:9.1f}", flush=True)
            next_hour += HOUR
    with tempfile.TemporaryDirectory() as tmp:
        outcome = TrialOutcome.of(processor, cfg, Path(args.config).read_text(), Path(tmp), truth=emulated_truth(cfg))
        verdict = outcome.write()
    print(f"{'outputs written':>15} {rss_mib():10.1f} {time.monotonic() - wall0:9.1f}   ({verdict})")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {peak:.1f} MiB, {sim.samples / (time.monotonic() - wall0):,.0f} samples/s over the whole run")


if __name__ == "__main__":
    main()
