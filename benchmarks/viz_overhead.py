"""Cost of Rerun logging per IMU sample at 200 Hz (or ``--rate``) with the default blueprint (save mode).

    .venv/bin/python benchmarks/viz_overhead.py [--duration 600] [--rate 200] [--batch-hz 10]

The trial's snapshots (1 Hz) and gimbal angles are computed first; then the live call pattern is
replayed as fast as possible, once with non-blocking calls and once waiting for the logging
thread: every 1/batch_hz s of trial time a ``log_table`` with the samples of that interval
(decimated to ``TABLE_RATE_HZ`` inside) and a ``log_temperature`` (logged once a second), every second a
``log_snapshot`` and a ``log_health`` with the figures a live trial gives (the pipeline's and the live queue's and
latencies) and a ``log_streams`` (the
verdict so far, judged against the config's ``output.limits``), at the end the trial's verdict (``end``). Running far
faster than real time, the caller competes with the logging thread for the interpreter, so its
figure is pessimistic.
Prints, per IMU sample:
  caller   time spent inside the (non-blocking) TrialViewer calls: what the processing thread pays,
  total    CPU time of the whole process from opening to a complete .rrd with nothing dropped
           (logging thread and Rerun's own threads included): what the trial costs the machine,
and the same for the batched path (``log_snapshots``, simulate and replay) and the .rrd sizes (MB per
trial minute: docs/viewer.md states the live one).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from emulators.simulation import Simulation
from hil.config import load_config
from hil.estimation.online import OnlineEstimator
from hil.samples import StreamCounts
from hil.units import UG
from hil.viewer.bias_view import BiasTruth
from hil.viewer.modes import ViewerOptions
from hil.viewer.trial_viewer import TABLE_RATE_HZ, TrialViewer

HEALTH = {  # what a live trial gives (hil.pipeline.processor and hil.trial.live)
    "imu": {"frames": 0, "corrupt": 0, "missing": 0, "outages": 0},
    "table": {"frames": 0, "corrupt": 0, "missing": 0, "outages": 0},
    "aligner": {"aligned": 0, "filled": 0, "bridged": 0, "without_angles": 0, "queue": 1,
                "latency_p50_ms": 2.0, "latency_p99_ms": 4.5, "latency_max_ms": 9.0,
                "age_p50_ms": 3.0, "age_p99_ms": 6.0, "age_max_ms": 12.0},
}


def trial(duration: float, rate: float):
    cfg = load_config("configs/emulated_swing.yaml")  # the default trial, shortened
    cfg = cfg.model_copy(update={"trial": cfg.trial.model_copy(update={"duration_s": duration, "rate_hz": rate})})
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0)
    t, angles = [], []
    for batch in sim.batches():
        est.update_many(batch)
        t.append(batch.t)
        angles.append(batch.angles)
    return cfg, sim, est.snapshots, np.concatenate(t), np.vstack(angles)


def live(cfg, sim, snapshots, t, angles, batch_hz: float, out: Path, blocking: bool) -> dict:
    per_batch = max(1, round(len(t) / (t[-1] * batch_hz)))
    snaps = iter(snapshots)
    next_snap = next(snaps, None)
    caller = 0.0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    c0 = time.perf_counter()
    viewer = TrialViewer(ViewerOptions("save"), out, geometry=sim.truth.geometry,
                         truth=BiasTruth(np.array([60, 150, 260]) * UG), limits=cfg.limits, blocking=blocking,
                         verdict_at_end=True)
    caller += time.perf_counter() - c0
    for start in range(0, len(t), per_batch):
        stop = min(start + per_batch, len(t))
        c0 = time.perf_counter()
        viewer.log_table(t[start:stop], angles[start:stop])
        viewer.log_temperature(t[stop - 1], 25.0)  # each progress carries the IMU's temperature
        while next_snap is not None and next_snap.t <= t[stop - 1]:
            viewer.log_snapshot(next_snap)
            viewer.log_health(next_snap.t, HEALTH)
            viewer.log_streams(StreamCounts(next_snap.samples, next_snap.samples, next_snap.samples))
            next_snap = next(snaps, None)
        caller += time.perf_counter() - c0
    c0 = time.perf_counter()
    viewer.end("## Verdict: PASS\n")
    close = time.perf_counter() - c0
    return {"caller": caller, "close": close, "cpu": time.process_time() - cpu0, "wall": time.perf_counter() - wall0,
            "dropped": viewer.dropped, "size": (out / "recording.rrd").stat().st_size}  # fmt: skip


def batched(sim, snapshots, t, angles, out: Path) -> dict:
    cpu0, wall0 = time.process_time(), time.perf_counter()
    viewer = TrialViewer(ViewerOptions("save"), out, geometry=sim.truth.geometry,
                         truth=BiasTruth(np.array([60, 150, 260]) * UG), blocking=True)
    for start in range(0, len(t), 20000):
        viewer.log_table(t[start : start + 20000], angles[start : start + 20000])
    viewer.log_snapshots(snapshots)
    viewer.close()
    return {"cpu": time.process_time() - cpu0, "wall": time.perf_counter() - wall0,
            "size": (out / "recording.rrd").stat().st_size}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=600.0, help="trial seconds (default 600)")
    parser.add_argument("--rate", type=float, default=200.0, help="IMU rate, Hz (default 200)")
    parser.add_argument("--batch-hz", type=float, default=10.0, help="log_table calls per second (default 10)")
    args = parser.parse_args()
    cfg, sim, snapshots, t, angles = trial(args.duration, args.rate)
    n = len(t)
    with tempfile.TemporaryDirectory() as tmp:
        # the calls come ~1000x faster than in a real trial: without blocking the queue overflows and
        # calls are dropped (the caller's own cost); with blocking nothing is lost (the full cost)
        free = live(cfg, sim, snapshots, t, angles, args.batch_hz, Path(tmp) / "free", blocking=False)
        trial_live = live(cfg, sim, snapshots, t, angles, args.batch_hz, Path(tmp) / "live", blocking=True)
        trial_batch = batched(sim, snapshots, t, angles, Path(tmp) / "batch")
    us = 1e6 / n
    print(f"trial: {args.duration:.0f} s at {args.rate:.0f} Hz = {n} samples, {len(snapshots)} snapshots, "
          f"table decimated to {TABLE_RATE_HZ:.0f} Hz, save mode, default blueprint")  # fmt: skip
    print(f"live calls (log_table at {args.batch_hz:.0f} Hz, log_snapshot + log_health at 1 Hz)")
    print(f"  caller (processing thread)   {free['caller'] * us:7.2f} us/sample (non-blocking calls)")
    print(f"  end (verdict, finish .rrd)   {trial_live['close'] * 1e3:7.1f} ms")
    print(f"  total CPU, all threads       {trial_live['cpu'] * us:7.2f} us/sample "
          f"({100 * trial_live['cpu'] / args.duration:.2f} % of one core in real time)")  # fmt: skip
    print(f"  wall time, 600x+ real time   {trial_live['wall']:7.2f} s (dropped calls: {trial_live['dropped']})")
    print(f"  recording.rrd                {trial_live['size'] / 1e6:7.2f} MB "
          f"({trial_live['size'] / 1e6 / (args.duration / 60):.3f} MB per trial minute)")  # fmt: skip
    print("batched (log_snapshots, table in 20000-sample batches: simulate, replay)")
    print(f"  total CPU, all threads       {trial_batch['cpu'] * us:7.2f} us/sample, wall {trial_batch['wall']:.2f} s")
    print(f"  recording.rrd                {trial_batch['size'] / 1e6:7.2f} MB "
          f"({trial_batch['size'] / 1e6 / (args.duration / 60):.3f} MB per trial minute)")  # fmt: skip


if __name__ == "__main__":
    main()
