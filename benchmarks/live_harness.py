"""The live harness at real time: CPU share of the harness process, latency, memory.

Runs the default emulated trial (emulated devices in their own process) through the harness in
this process and prints: CPU time of this process over the trial (share of one core), the frames
dropped and counted corrupt, the chunk-arrival -> estimator-updated latency and age p50/p99/max, the
frame age (from the moment the emulator wrote the oldest sample's frame: the chunk ages leave out the
time it waited in the port for the read), the resident memory every minute, and the machine's load average before and after (the machine is shared).
``--imu-rate`` runs the IMU faster than the table (1000 or 2000 Hz: one pulse train at the IMU rate,
the table latching every n-th pulse at ``trial.rate_hz``). ``--lab`` is the lab form, the figure that counts:
the emulator streams from its start as powered hardware does (its counters from their own starts), and the
harness attaches ``--late`` seconds later and pairs the counters from the data.

    .venv/bin/python benchmarks/live_harness.py [--duration 600] [--config configs/emulated_swing.yaml]
        [--imu-rate HZ] [--batch N] [--lab [--late S]]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import yaml

from emulators.clocks import counter_starts
from emulators.process import EmulatorRun, spawn_emulator, stop_emulator
from hil.config import load_config
from hil.pipeline.progress import Progress
from hil.trial.live import LiveSettings, LiveTrial, TrialHooks
from hil.trial.rig import data_links
from hil.vocabulary import DevicePorts


def rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def thread_cpu() -> dict[str, float]:
    """CPU seconds (user + system) of each live thread of this process, by thread name."""
    tick = os.sysconf("SC_CLK_TCK")
    out = {}
    for thread in threading.enumerate():
        try:
            fields = Path(f"/proc/self/task/{thread.native_id}/stat").read_text().rpartition(")")[2].split()
        except (FileNotFoundError, TypeError):
            continue
        out[thread.name] = (int(fields[11]) + int(fields[12])) / tick
    return out


class FrameAges:
    """How old the oldest sample is when the estimator takes it, counted from the moment the emulator wrote its
    frame (the emulator's clock start, from its stats, places its ticks on this host's monotonic clock): what
    the chunk ages leave out is the time the frame waited in the port for the read."""

    def __init__(self) -> None:
        self.updates: list[tuple[float, float]] = []  # (monotonic time, trial time of the oldest sample taken)

    def on_progress(self, progress: Progress) -> None:
        """A listener of the pipeline: when each run of samples was taken."""
        now = time.monotonic()
        self.updates += [(now, float(run.t[0])) for run in progress.samples()]

    def percentiles_ms(self, started: float, t0: float, delay: float, table_start: float) -> tuple[float, float, float]:
        """p50, p99 and max (ms) given the emulator's clock start (monotonic), the estimator's t0, the IMU's latch
        delay and the table counter's start (s of pulses): the sample of pulse p (the table's count), at trial
        time p / rate + delay, was written at started + p / rate - table_start."""
        now, t = np.array(self.updates).T
        return tuple(1e3 * np.percentile(now - (started + t + t0 - delay - table_start), [50, 99, 100]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=600.0)
    parser.add_argument("--config", default="configs/emulated_swing.yaml")
    parser.add_argument("--imu-rate", type=float, help="imu.rate_hz (default: the config's); the table keeps its rate")
    parser.add_argument("--batch", type=int, help="estimator.batch_samples (default: the config's)")
    parser.add_argument("--lab", action="store_true", help="the emulator streams from its start; the harness attaches late")
    parser.add_argument("--late", type=float, default=2.0, help="--lab: s from the emulator's start to the harness's")
    args = parser.parse_args()
    text = Path(args.config).read_text()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        config = Path(args.config)
        if args.imu_rate is not None:
            data = yaml.safe_load(text)
            data["imu"]["rate_hz"] = args.imu_rate
            text = yaml.safe_dump(data)
            config = out / "config.yaml"
            config.write_text(text)
        cfg = load_config(config)
        if args.batch is not None:
            cfg = cfg.model_copy(update={"estimator": cfg.estimator.model_copy(update={"batch_samples": args.batch})})
        late = args.late if args.lab else 0.0
        run = EmulatorRun("1", args.duration + late + 5.0, not args.lab, stats_file=out / "emulator.json")
        emulator, ports = spawn_emulator(config, out / "ports.json", run)
        time.sleep(late)
        frames = FrameAges()
        trial = LiveTrial(LiveSettings.of(cfg), text, out, args.duration, data_links(cfg, DevicePorts.of(ports)), hooks=TrialHooks(
            source_done=lambda: emulator.poll() is not None, listeners=(frames.on_progress,)))
        memory: list[tuple[float, float]] = []

        def trial_time() -> float:
            return trial.progress.trial_time if trial.progress is not None else 0.0
        stop = threading.Event()

        threads: dict[str, float] = {}

        def sample_memory() -> None:
            ticks = 0
            while not stop.wait(1.0):
                threads.update(thread_cpu())  # the readers' last second is lost: they end with the trial
                ticks += 1
                if ticks % 60 == 0:
                    memory.append((trial_time(), rss_mib()))

        watcher = threading.Thread(target=sample_memory, daemon=True)
        watcher.start()
        memory.append((0.0, rss_mib()))
        cpu0, wall0 = resource.getrusage(resource.RUSAGE_SELF), time.monotonic()
        trial.run()
        cpu1, wall1 = resource.getrusage(resource.RUSAGE_SELF), time.monotonic()
        stop.set()
        stop_emulator(emulator) if args.lab else emulator.wait()  # lab: the devices stream on, as hardware does
        memory.append((trial_time(), rss_mib()))
        cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
        wall = wall1 - wall0
        lat = trial.latency.percentiles_ms()
        counts = trial.finished.streams
        load_after = os.getloadavg()
        print(f"imu {cfg.imu_rate_hz:g} Hz ({cfg.imu.protocol}), table {cfg.trial.rate_hz:g} Hz, "
              f"estimator.batch_samples {cfg.block_samples}; load average (1, 5, 15 min) before "
              + " ".join(f"{x:.2f}" for x in load_before) + ", after " + " ".join(f"{x:.2f}" for x in load_after))
        print(f"trial {trial_time():.1f} s of data in {wall:.1f} s wall; "
              f"{counts.aligned} samples aligned, {counts.dropped} dropped, {counts.corrupt} corrupt, "
              f"{counts.extra['imu_unpaired']} unpaired, {counts.extra['imu_gated']} gated")
        print("sync pairing: " + json.dumps(counts.extra["sync"]) + (
            f" (attached {late:g} s after the devices started)" if args.lab else ""))
        print(f"harness CPU: {cpu:.2f} s = {100 * cpu / wall:.1f} % of one core "
              f"({1e6 * cpu / max(counts.aligned, 1):.0f} us per IMU sample, all threads)")
        print("chunk arrival -> estimate updated, ms (latency: from the chunk completing a block; age: from the "
              "chunk that completed its oldest sample): " + ", ".join(f"{k.removesuffix('_ms')} {v:.2f}" for k, v in lat.items()))
        stats = json.loads((out / "emulator.json").read_text())
        written = ", ".join(f"{name} {device['frames']} frames" for name, device in stats["devices"].items())
        print(f"emulator (its own process): {stats['pulses']} pulses in {stats['elapsed_s']:.1f} s, {written}")
        table_start = counter_starts(cfg)[1] / cfg.imu_rate_hz
        ages = frames.percentiles_ms(stats["started"], trial.finished.estimator.t0, cfg.imu.latch_delay_us * 1e-6,
                                     table_start)
        print("frame written -> estimate updated, ms (the oldest sample taken, its wait in the port included): "
              "p50 {:.2f}, p99 {:.2f}, max {:.2f}".format(*ages))
        threads.update(thread_cpu())
        print("CPU by thread, s (to its last second): " + ", ".join(f"{name} {s:.2f}" for name, s in sorted(threads.items())))
        print("resident memory (trial s, MiB): " + ", ".join(f"({t:.0f}, {m:.1f})" for t, m in memory))


if __name__ == "__main__":
    main()
