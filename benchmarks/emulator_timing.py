"""Emulator timing at real time: pulse-to-write latency, frame interval jitter at a reader, emulator CPU.

    python benchmarks/emulator_timing.py [--duration 60] [--rate 200] [CONFIG]

Starts ``python -m emulators`` in its own process at speed 1, reads both ptys from this
process with plain ``os.read`` and times each complete frame's arrival. Prints, per device: the
emulator's pulse-to-frame-written latency (p50, p99; includes the wire time at the configured
baudrate), the reader's frame intervals (std, p99 of |interval - 1/rate|), and the emulator's CPU use.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil
import yaml

from drivers.registry import imu_codec
from drivers.tts1 import Tts1Codec
from emulators.process import EmulatorRun, spawn_emulator
from hil.config import load_config


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="configs/emulated_swing.yaml")
    parser.add_argument("--duration", type=float, default=60.0, help="s of real time (default 60)")
    parser.add_argument("--rate", type=float, default=200.0, help="sync pulse rate, Hz (default 200)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        data = yaml.safe_load(Path(args.config).read_text())
        data["trial"].update(duration_s=args.duration, rate_hz=args.rate)
        data.get("imu", {}).pop("rate_hz", None)
        config = Path(tmp) / "trial.yaml"
        config.write_text(yaml.safe_dump(data))
        cfg = load_config(config)
        stats_file = Path(tmp) / "stats.json"
        proc, ports = spawn_emulator(config, Path(tmp) / "ports.json",
                                     EmulatorRun("1", wait_readers=True, stats_file=stats_file))
        emulator = psutil.Process(proc.pid)
        arrivals, cpu = read_frames(ports, cfg, proc, emulator)
        proc.wait(30)
        stats = json.loads(stats_file.read_text())
    wall = stats["elapsed_s"]
    print(f"{args.rate:g} Hz, {args.duration:g} s at real time, {stats['pulses']} pulses in {wall:.2f} s")
    for name, times in arrivals.items():
        device = stats["devices"][name]
        interval = np.diff(times)
        off = np.abs(interval - 1.0 / args.rate) * 1e3
        print(f"  {name:15s} frames {len(times):6d}  pulse-to-write p50 {device['latency_p50_ms']:.3f} ms "
              f"p99 {device['latency_p99_ms']:.3f} ms  reader interval std {np.std(interval) * 1e3:.3f} ms, "
              f"p99 |dt - {1e3 / args.rate:g} ms| {np.percentile(off, 99):.3f} ms, max {off.max():.3f} ms")
    span = max(t[-1] for t in arrivals.values()) - min(t[0] for t in arrivals.values())
    print(f"  emulator CPU {cpu:.2f} s over the {span:.2f} s of frames: {100 * cpu / span:.1f} % of one core")
    return 0


def read_frames(ports: dict, cfg, proc, emulator: psutil.Process) -> tuple[dict[str, np.ndarray], float]:
    """Arrival times (monotonic, s) of every complete frame on each pty; the emulator's CPU seconds from
    its first frame to its last (start-up, mostly imports, left out)."""
    framers = {"imu": imu_codec(cfg.imu, cfg.imu_rate_hz).framer(), "turntable_data": Tts1Codec().framer()}
    fds = {os.open(ports[name], os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK): name for name in framers}
    arrivals: dict[str, list[float]] = {name: [] for name in framers}
    cpu, cpu_start = 0.0, None
    try:
        while fds:
            ready, _, _ = select.select(list(fds), [], [], 0.5)
            now = time.monotonic()
            for fd in ready:
                try:
                    data = os.read(fd, 65536)
                except OSError:
                    data = b""
                if not data:  # the emulator closed the port: the run is over
                    os.close(fd)
                    del fds[fd]
                    continue
                name = fds[fd]
                arrivals[name] += [now] * len(framers[name].feed_bytes(data, now))
            if proc.poll() is None:
                try:
                    times = emulator.cpu_times()
                except psutil.Error:
                    continue
                cpu = times.user + times.system
                if cpu_start is None and any(arrivals.values()):
                    cpu_start = cpu
    finally:
        for fd in fds:
            os.close(fd)
    return {name: np.array(times) for name, times in arrivals.items()}, cpu - (cpu_start or 0.0)


if __name__ == "__main__":
    sys.exit(main())
