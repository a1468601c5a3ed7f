"""Cost of one display solve (``OnlineEstimator._snapshot``) in the 2019 paper's scenario.

The scenario of ``hil simulate configs/liu2019_sim.yaml`` (4000 s at 100 Hz, a solve every 5 s: 800
snapshots) is emulated once; the estimator then runs over it ``--repeat`` times with every snapshot
timed where it happens (between batches, as in the trial: caches as the batch work leaves them), and
``--loop`` further snapshots are taken back to back at the end of the trial (warm caches).

    PYTHONPATH=. .venv/bin/python benchmarks/snapshot_cost.py [--repeat 3] [--loop 2000]

Prints the median and mean per-snapshot cost in us of the in-trial snapshots (median over the
repeats), the estimator's whole time over the trial and the snapshots' share of it, and the
per-snapshot cost of the back-to-back loop (median over blocks of 100). Run it on two trees
alternately (``PYTHONPATH=tree-a``, ``PYTHONPATH=tree-b``) to compare them; the machine's load moves
both.
"""

from __future__ import annotations

import argparse
import statistics
import time

from emulators.simulation import Simulation
from hil.config import load_config
from hil.estimation.online import OnlineEstimator

CONFIG = "configs/liu2019_sim.yaml"


class TimedEstimator(OnlineEstimator):
    """The estimator with the wall time of every snapshot kept."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.costs: list[float] = []

    def _snapshot(self):
        t0 = time.perf_counter()
        snap = super()._snapshot()
        self.costs.append(time.perf_counter() - t0)
        return snap


def in_trial(sim: Simulation, batches: list, period: float) -> TimedEstimator:
    est = TimedEstimator(sim.truth.earth, sim.truth.geometry, solve_period=period)
    for batch in batches:
        est.update_many(batch)
    return est


def back_to_back(est: OnlineEstimator, n: int, block: int = 100) -> float:
    """Seconds per snapshot of ``n`` snapshots of the same state one after the other: the median over
    blocks of ``block``."""
    snapshot = OnlineEstimator._snapshot
    costs = []
    for _ in range(max(1, n // block)):
        t0 = time.perf_counter()
        for _ in range(block):
            snapshot(est)
        costs.append((time.perf_counter() - t0) / block)
    return statistics.median(costs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=3, help="runs of the estimator over the trial")
    parser.add_argument("--loop", type=int, default=2000, help="back-to-back snapshots at the end")
    args = parser.parse_args()
    cfg = load_config(CONFIG)
    sim = Simulation.from_config(cfg)
    batches = list(sim.batches())
    period = 1.0 / cfg.estimator.solve_rate_hz
    medians, means, totals = [], [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        est = in_trial(sim, batches, period)
        totals.append(time.perf_counter() - t0)
        medians.append(statistics.median(est.costs))
        means.append(statistics.fmean(est.costs))
    loop = back_to_back(est, args.loop)
    print(f"snapshots per run               {len(est.costs)}")
    print(f"in trial, per snapshot          {statistics.median(medians) * 1e6:.0f} us median"
          f"   {statistics.median(means) * 1e6:.0f} us mean   (median of {args.repeat} runs)")
    print(f"estimation of the trial         {statistics.median(totals):.3f} s   of which the snapshots"
          f" {statistics.median(means) * len(est.costs):.3f} s   (medians)")
    print(f"back to back, per snapshot      {loop * 1e6:.0f} us   (median of blocks of 100, {args.loop} at the end"
          " of the trial)")


if __name__ == "__main__":
    main()
