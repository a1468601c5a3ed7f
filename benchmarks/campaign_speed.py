"""Speed of `hil campaign`: runs/s on a LocalCluster of 1 and 2 workers beside the same runs called serially in
this process, and the scheduler's overhead per run: one worker's wall time minus the serial time, per run,
and the wall time per task of the same tasks mapped to a function that does nothing.
The runs are the 2019 paper's swing (``--kind noise``: the static record of configs/noise_static.yaml and its
Allan analysis; ``--kind calibration``: the calibration of configs/calibration_short.yaml, whose schedule sets
its length), short by default so that the overhead shows; each figure is the best of --repeat passes
(the machine's other load only ever slows a pass down).

    .venv/bin/python benchmarks/campaign_speed.py [--kind swing] [--runs 40] [--duration 60] [--rate 100] [--repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import yaml

from hil.campaign.cluster import open_client
from hil.campaign.kinds import KINDS
from hil.campaign.runner import gather
from hil.campaign.spec import load_campaign

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
BASES = {"swing": CONFIGS / "liu2019_sim.yaml", "noise": CONFIGS / "noise_static.yaml",
         "calibration": CONFIGS / "calibration_short.yaml"}


def nothing(task):
    """A task's round trip without its run: the task shipped, a small row back."""
    return {"id": task.id}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kind", choices=sorted(BASES), default="swing")
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--duration", type=float, default=60.0, help="s of each trial")
    parser.add_argument("--rate", type=float, default=100.0, help="Hz")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "speed.yaml"
        sweep = {"trial.rate_hz": [args.rate]}
        if args.kind != "calibration":
            sweep["trial.duration_s"] = [args.duration]
        spec.write_text(yaml.safe_dump({"base": str(BASES[args.kind]), "kind": args.kind, "runs": args.runs, "seed": 1,
                                        "sweep": sweep}))
        tasks = load_campaign(spec).tasks
        run_one = KINDS[args.kind].run
        run_one(tasks[0])  # imports and caches warm, as on a worker after its first run
        serial_s = float("inf")
        for _ in range(args.repeat):
            start = time.perf_counter()
            serial = [run_one(task) for task in tasks]
            serial_s = min(serial_s, time.perf_counter() - start)
        length = "its schedule" if args.kind == "calibration" else f"{args.duration:g} s"
        print(f"{args.runs} {args.kind} runs of {length} at {args.rate:g} Hz")
        print(f"serial, in process: {serial_s:7.2f} s, {args.runs / serial_s:6.2f} runs/s, "
              f"{serial_s / args.runs * 1e3:7.1f} ms a run")
        one_worker_s = None
        for workers in (1, 2):
            start = time.perf_counter()
            with open_client(None, workers) as (client, _):
                started = time.perf_counter()
                client.run(run_one, tasks[0])  # each worker's imports, outside the timing
                warm = time.perf_counter()
                wall = float("inf")
                for _ in range(args.repeat):
                    start_pass, rows = time.perf_counter(), []
                    gather(client, run_one, tasks, rows, Path(tmp))
                    wall = min(wall, time.perf_counter() - start_pass)
                    assert sorted(rows, key=lambda r: r["id"]) == serial, "the cluster's rows differ from the serial ones"
                empty = float("inf")
                for _ in range(args.repeat):
                    start_pass = time.perf_counter()
                    client.gather(client.map(nothing, tasks, pure=False))
                    empty = min(empty, time.perf_counter() - start_pass)
            one_worker_s = one_worker_s or wall
            print(f"{workers} worker(s): {wall:7.2f} s, {args.runs / wall:6.2f} runs/s (cluster start "
                  f"{started - start:.1f} s, worker imports {warm - started:.1f} s); an empty task "
                  f"{empty / args.runs * 1e3:.1f} ms")
        print(f"scheduler overhead per run (1 worker minus serial): {(one_worker_s - serial_s) / args.runs * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
