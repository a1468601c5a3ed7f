"""What one campaign run costs beyond its simulation and estimation: a swing run of the 2019 paper's scenario
(configs/liu2019_sim.yaml, 400 000 samples) as a worker takes it (``hil.campaign.runs.run_swing``, warm: the
worker's imports done by an earlier run), profiled; prints the run's time, the time in the emulator's batches
and in the estimator's (``Simulation.batches``, ``TrialProcessor.feed_batch``), the rest of the trial, what the run
does outside it (config validation, the config's YAML text, the row), the profile's top five by own time,
and the load average. (cProfile charges a generator's resumptions to it: the parts are to its resolution.)

    .venv/bin/python benchmarks/run_cost.py
"""

from __future__ import annotations

import cProfile
import io
import os
import pstats
import tempfile
from pathlib import Path

import yaml

from hil.campaign.runs import run_swing
from hil.campaign.spec import load_campaign

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "liu2019_sim.yaml"
PARTS = {"run": ("runs.py", "run_swing"), "trial": ("offline.py", "run_simulation"),
         "simulation": ("simulation.py", "batches"), "estimation": ("processor.py", "feed_batch")}


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "spec.yaml"
        spec.write_text(yaml.safe_dump({"base": str(CONFIG), "runs": 2, "seed": 1}))
        first, task = load_campaign(spec).tasks
    run_swing(first)
    profile = cProfile.Profile()
    profile.runcall(run_swing, task)
    stats = pstats.Stats(profile)
    cumulative = {(Path(file).name, name): entry[3] for (file, _, name), entry in stats.stats.items()}
    t = {part: cumulative[where] for part, where in PARTS.items()}
    run = t["run"]
    print(f"one swing run, profiled: {run:.3f} s (load average {os.getloadavg()[0]:.1f})")
    for label, seconds in (("the emulator's batches", t["simulation"]), ("the estimator's batches", t["estimation"]),
                           ("rest of the trial (setup, result document)", t["trial"] - t["simulation"] - t["estimation"]),
                           ("outside the trial (config validation, YAML text, row)", run - t["trial"])):
        print(f"  {label:<55} {seconds:7.3f} s {seconds / run:6.1%}")
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(5)
    lines = text.getvalue().splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip().startswith("ncalls"))
    print("profile, top five by own time:")
    for line in lines[start:start + 6]:
        print(f"    {line.strip()}")


if __name__ == "__main__":
    main()
