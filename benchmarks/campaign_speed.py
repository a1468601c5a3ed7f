"""Speed of `hil campaign`: runs/s on a LocalCluster of 1 and 2 workers beside the same runs called serially in
this process, and the scheduler's overhead per run: one worker's wall time minus the serial time, per run,
and the wall time per task of the same tasks mapped to a function that does nothing.
The runs are the 2019 paper's swing (``--kind noise``: the static record of configs/noise_static.yaml and its
Allan analysis; ``--kind calibration``: the calibration of configs/calibration_short.yaml, whose schedule sets
its length), short by default so that the overhead shows; each figure is the best of --repeat passes
(the machine's other load only ever slows a pass down).
With ``--scheduler``: the same runs side by side on three clusters of --workers single-threaded workers, all up
at once and taken in turn every pass (each first in turn): a LocalCluster, an existing cluster (a scheduler on 127.0.0.1) whose
workers `hil worker` started, and one whose workers a plain `dask worker` started (dask's defaults: the
profiler on, MALLOC_TRIM_THRESHOLD_=65536); each figure with the load average of its best pass.

    .venv/bin/python benchmarks/campaign_speed.py [--kind swing] [--runs 40] [--duration 60] [--rate 100] [--repeat 3]
    .venv/bin/python benchmarks/campaign_speed.py --scheduler [--workers 2] [--runs 20] [--duration 600]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
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


def _stopped(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()


@contextmanager
def existing_cluster(tmp: Path, workers: list[str]) -> Iterator[str]:
    """A scheduler on 127.0.0.1 and the workers ``workers`` (``python -m`` arguments, the scheduler's address
    in place of ADDRESS) start; the scheduler's address."""
    info = tmp / f"scheduler-{time.monotonic_ns()}.json"
    python = [sys.executable, "-m"]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen(python + ["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                                           "--dashboard-address", "127.0.0.1:0", "--scheduler-file", str(info)], **quiet)
    try:
        while not info.exists() or not info.read_text():
            assert scheduler.poll() is None, "the scheduler did not start"
            time.sleep(0.2)
        address = json.loads(info.read_text())["address"]
        started = subprocess.Popen(python + [address if a == "ADDRESS" else a for a in workers], **quiet)
        try:
            yield address
        finally:
            _stopped(started)
    finally:
        _stopped(scheduler)


def compare_clusters(args: argparse.Namespace, tasks: list, run_swing, serial: list, tmp: Path) -> None:
    """runs/s of the same runs on a LocalCluster, on `hil worker` workers and on plain `dask worker` ones."""
    from distributed import Client

    n = str(args.workers)
    loopback = ["--host", "127.0.0.1", "--nworkers", n]
    plain = ["distributed.cli.dask_worker", "ADDRESS", *loopback, "--nthreads", "1", "--dashboard-address", "127.0.0.1:0"]
    with ExitStack() as stack:
        clients = {"LocalCluster": stack.enter_context(open_client(None, args.workers))[0]}
        for name, workers in (("hil worker", ["hil.cli", "worker", "ADDRESS", *loopback]), ("dask worker", plain)):
            address = stack.enter_context(existing_cluster(tmp, workers))
            clients[name] = stack.enter_context(Client(address, timeout=30))
            clients[name].wait_for_workers(args.workers, timeout=120)
        best = {name: (float("inf"), 0.0) for name in clients}
        for client in clients.values():
            client.run(run_swing, tasks[0])  # each worker's imports, outside the timing
        for k in range(args.repeat):
            names = list(clients)
            for name in names[k % 3:] + names[:k % 3]:  # each cluster first in turn: the load drifts
                client = clients[name]
                start, rows = time.perf_counter(), []
                gather(client, run_swing, tasks, rows, tmp)
                wall = time.perf_counter() - start
                assert sorted(rows, key=lambda r: r["id"]) == serial, f"{name}: the rows differ from the serial ones"
                best[name] = min(best[name], (wall, os.getloadavg()[0]))
    local = args.runs / best["LocalCluster"][0]
    for name, (wall, load) in best.items():
        print(f"{name:>12}, {args.workers} workers: {wall:7.2f} s, {args.runs / wall:6.2f} runs/s, "
              f"{args.runs / wall / local:5.2f} of the LocalCluster's (load average {load:.1f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kind", choices=sorted(BASES), default="swing")
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--duration", type=float, default=60.0, help="s of each trial")
    parser.add_argument("--rate", type=float, default=100.0, help="Hz")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scheduler", action="store_true", help="LocalCluster, `hil worker` and `dask worker` "
                                                                  "side by side")
    parser.add_argument("--workers", type=int, default=2, help="--scheduler: each cluster's workers")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "speed.yaml"
        sweep = {"trial.rate_hz": [args.rate]}
        if args.kind != "calibration":
            sweep["trial.duration_s"] = [args.duration]
        spec.write_text(yaml.safe_dump({"base": str(BASES[args.kind]), "kind": args.kind, "runs": args.runs, "seed": 1,
                                        "sweep": sweep}))
        tasks = load_campaign(spec).tasks
        run_swing = KINDS[args.kind].run
        run_swing(tasks[0])  # imports and caches warm, as on a worker after its first run
        serial_s = float("inf")
        for _ in range(args.repeat):
            start = time.perf_counter()
            serial = [run_swing(task) for task in tasks]
            serial_s = min(serial_s, time.perf_counter() - start)
        length = "its schedule" if args.kind == "calibration" else f"{args.duration:g} s"
        print(f"{args.runs} {args.kind} runs of {length} at {args.rate:g} Hz")
        print(f"serial, in process: {serial_s:7.2f} s, {args.runs / serial_s:6.2f} runs/s, "
              f"{serial_s / args.runs * 1e3:7.1f} ms a run (load average {os.getloadavg()[0]:.1f})")
        if args.scheduler:
            compare_clusters(args, tasks, run_swing, serial, Path(tmp))
            return
        one_worker_s = None
        for workers in (1, 2):
            start = time.perf_counter()
            with open_client(None, workers) as (client, _):
                started = time.perf_counter()
                client.run(run_swing, tasks[0])  # each worker's imports, outside the timing
                warm = time.perf_counter()
                wall = float("inf")
                for _ in range(args.repeat):
                    start_pass, rows = time.perf_counter(), []
                    gather(client, run_swing, tasks, rows, Path(tmp))
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
