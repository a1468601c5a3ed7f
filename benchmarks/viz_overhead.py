"""Cost of Rerun logging per IMU sample at 200 Hz (or ``--rate``) with the default blueprint (save mode).

    .venv/bin/python benchmarks/viz_overhead.py [--duration 600] [--rate 200] [--batch-hz 10] [--units 1]

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

``--units N`` (N >= 2): a trial of N units on one table as ``hil run`` of a units config logs it, N TrialViewers
(one a unit, each its own recording) and the fixture's overview (:class:`~hil.viewer.fixture_view.FixtureView`, fed
each unit's snapshots; at the end each unit's verdict and the fixture's table), the units' calls interleaved in one
thread (a units trial makes them from a thread per unit); the figures are then per sample of each unit (the
fixture's cost divided by N times the samples) and the whole fixture's share of one core.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulators.simulation import Simulation
from hil.config import load_config
from hil.estimation.online import OnlineEstimator
from hil.samples import StreamCounts
from hil.units import UG
from hil.viewer.bias_view import BiasTruth
from hil.viewer.fixture_view import FixtureView
from hil.viewer.modes import ViewerOptions
from hil.viewer.trial_viewer import TABLE_RATE_HZ, TrialViewer

HEALTH = {  # what a live trial gives (hil.pipeline.processor and hil.trial.live)
    "imu": {"frames": 0, "corrupt": 0, "missing": 0, "outages": 0},
    "table": {"frames": 0, "corrupt": 0, "missing": 0, "outages": 0},
    "aligner": {"aligned": 0, "filled": 0, "bridged": 0, "without_angles": 0, "queue": 1,
                "latency_p50_ms": 2.0, "latency_p99_ms": 4.5, "latency_max_ms": 9.0,
                "age_p50_ms": 3.0, "age_p99_ms": 6.0, "age_max_ms": 12.0},
}


@dataclass(frozen=True)
class Trial:
    """The simulated trial whose calls are replayed: its config, simulation, 1 Hz snapshots, sample times and
    gimbal angles."""

    cfg: object
    sim: Simulation
    snapshots: list
    t: np.ndarray
    angles: np.ndarray


def trial(duration: float, rate: float) -> Trial:
    cfg = load_config("configs/emulated_swing.yaml")  # the default trial, shortened
    cfg = cfg.model_copy(update={"trial": cfg.trial.model_copy(update={"duration_s": duration, "rate_hz": rate})})
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0)
    t, angles = [], []
    for batch in sim.batches():
        est.update_many(batch)
        t.append(batch.t)
        angles.append(batch.angles)
    return Trial(cfg, sim, est.snapshots, np.concatenate(t), np.vstack(angles))


def live(run: Trial, batch_hz: float, out: Path, blocking: bool, units: int = 1) -> dict:
    """The live call pattern of ``units`` units (and with several, the fixture's overview) on ``run``'s trial."""
    t, angles = run.t, run.angles
    per_batch = max(1, round(len(t) / (t[-1] * batch_hz)))
    snaps = iter(run.snapshots)
    next_snap = next(snaps, None)
    truth = BiasTruth(np.array([60, 150, 260]) * UG)
    names = [f"unit{k}" for k in range(units)] if units > 1 else ["trial"]
    caller = 0.0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    c0 = time.perf_counter()
    viewers = [TrialViewer(ViewerOptions("save"), out if units == 1 else out / "units" / name,
                           geometry=run.sim.truth.geometry, truth=truth, limits=run.cfg.limits, recording_name=name,
                           blocking=blocking, verdict_at_end=True) for name in names]  # fmt: skip
    overview = None
    if units > 1:
        overview = FixtureView(ViewerOptions("save"), out, "fixture", blocking=blocking)
        for name in names:
            overview.listener(name, name.upper(), truth)
        overview.open(names, None)
    caller += time.perf_counter() - c0
    for start in range(0, len(t), per_batch):
        stop = min(start + per_batch, len(t))
        c0 = time.perf_counter()
        due = []
        while next_snap is not None and next_snap.t <= t[stop - 1]:
            due.append(next_snap)
            next_snap = next(snaps, None)
        for name, viewer in zip(names, viewers, strict=True):
            viewer.log_table(t[start:stop], angles[start:stop])
            viewer.log_temperature(t[stop - 1], 25.0)  # each progress carries the IMU's temperature
            for snap in due:
                viewer.log_snapshot(snap)
                viewer.log_health(snap.t, HEALTH)
                viewer.log_streams(StreamCounts(snap.samples, snap.samples, snap.samples))
            if overview is not None and due:
                overview.log_snapshots(name, due)  # what each unit's pipeline listener does
        caller += time.perf_counter() - c0
    c0 = time.perf_counter()
    for name, viewer in zip(names, viewers, strict=True):
        viewer.end("## Verdict: PASS\n")
        if overview is not None:
            overview.unit_verdict(name, "## Verdict: PASS\n")
    if overview is not None:
        overview.end({"ended": "completed", "verdict": "PASS", "units": [
            {"name": name, "dut_serial": name.upper(), "ended": "completed", "verdict": "PASS"} for name in names]})
    close = time.perf_counter() - c0
    sizes = [v.rrd_path.stat().st_size for v in viewers]
    return {"caller": caller, "close": close, "cpu": time.process_time() - cpu0, "wall": time.perf_counter() - wall0,
            "dropped": sum(v.dropped for v in viewers) + (overview.dropped if overview is not None else 0),
            "size": sum(sizes) / len(sizes),
            "fixture_size": overview.rrd_path.stat().st_size if overview is not None else None}  # fmt: skip


def batched(run: Trial, out: Path) -> dict:
    t, angles = run.t, run.angles
    cpu0, wall0 = time.process_time(), time.perf_counter()
    viewer = TrialViewer(ViewerOptions("save"), out, geometry=run.sim.truth.geometry,
                         truth=BiasTruth(np.array([60, 150, 260]) * UG), blocking=True)
    for start in range(0, len(t), 20000):
        viewer.log_table(t[start : start + 20000], angles[start : start + 20000])
    viewer.log_snapshots(run.snapshots)
    viewer.close()
    return {"cpu": time.process_time() - cpu0, "wall": time.perf_counter() - wall0,
            "size": (out / "recording.rrd").stat().st_size}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=600.0, help="trial seconds (default 600)")
    parser.add_argument("--rate", type=float, default=200.0, help="IMU rate, Hz (default 200)")
    parser.add_argument("--batch-hz", type=float, default=10.0, help="log_table calls per second (default 10)")
    parser.add_argument("--units", type=int, default=1,
                        help="units on the table (default 1; from 2, a TrialViewer each and the fixture's overview)")
    args = parser.parse_args()
    if args.units < 1:
        parser.error("--units: at least 1")
    run = trial(args.duration, args.rate)
    n, units = len(run.t), args.units
    with tempfile.TemporaryDirectory() as tmp:
        # the calls come ~1000x faster than in a real trial: without blocking the queue overflows and
        # calls are dropped (the caller's own cost); with blocking nothing is lost (the full cost)
        free = live(run, args.batch_hz, Path(tmp) / "free", blocking=False, units=units)
        trial_live = live(run, args.batch_hz, Path(tmp) / "live", blocking=True, units=units)
        trial_batch = batched(run, Path(tmp) / "batch")
    us = 1e6 / (n * units)
    minutes = args.duration / 60
    print(f"trial: {args.duration:.0f} s at {args.rate:.0f} Hz = {n} samples, {len(run.snapshots)} snapshots, "
          f"table decimated to {TABLE_RATE_HZ:.0f} Hz, save mode, default blueprint")  # fmt: skip
    if units > 1:
        print(f"units: {units}, a TrialViewer each and the fixture's overview; per sample of each unit "
              f"({n * units} in all)")  # fmt: skip
    print(f"live calls (log_table at {args.batch_hz:.0f} Hz, log_snapshot + log_health at 1 Hz)")
    print(f"  caller (processing thread)   {free['caller'] * us:7.2f} us/sample (non-blocking calls; "
          f"dropped: {free['dropped']})")  # fmt: skip
    print(f"  end (verdict, finish .rrd)   {trial_live['close'] * 1e3:7.1f} ms")
    print(f"  total CPU, all threads       {trial_live['cpu'] * us:7.2f} us/sample "
          f"({100 * trial_live['cpu'] / args.duration:.2f} % of one core in real time)")  # fmt: skip
    print(f"  wall time, 600x+ real time   {trial_live['wall']:7.2f} s (dropped calls: {trial_live['dropped']})")
    label = "recording.rrd (each unit's)" if units > 1 else "recording.rrd"
    print(f"  {label:<29}{trial_live['size'] / 1e6:7.2f} MB "
          f"({trial_live['size'] / 1e6 / minutes:.3f} MB per trial minute)")  # fmt: skip
    if trial_live["fixture_size"] is not None:
        print(f"  fixture.rrd                  {trial_live['fixture_size'] / 1e6:7.2f} MB "
              f"({trial_live['fixture_size'] / 1e6 / minutes:.3f} MB per trial minute)")  # fmt: skip
    print("batched (log_snapshots, table in 20000-sample batches: simulate, replay; one unit)")
    print(f"  total CPU, all threads       {trial_batch['cpu'] * 1e6 / n:7.2f} us/sample, "
          f"wall {trial_batch['wall']:.2f} s")  # fmt: skip
    print(f"  recording.rrd                {trial_batch['size'] / 1e6:7.2f} MB "
          f"({trial_batch['size'] / 1e6 / minutes:.3f} MB per trial minute)")  # fmt: skip


if __name__ == "__main__":
    main()
