"""Speed of `hil simulate` on the 2019 paper's scenario and per-sample estimator cost beside filterpy.

    PYTHONPATH=. .venv/bin/python benchmarks/simulate_speed.py   (filterpy is compared when installed:
                                                              pip install -e '.[bench]')
Prints: emulation and estimation time for the 400 000 samples, samples/s, the five functions the
profile of the two spends most time in, the whole command's wall time including start-up (first run:
the project's own modules compiled afresh, the installed packages as pip compiled them at install; every
module afresh: no bytecode at all, as with a read-only site-packages; warm: best of 3; with and without
figures), its peak RSS, the start-up time of ``hil --help``, and the per-sample cost of the 12-state update.
"""

from __future__ import annotations

import cProfile
import io
import os
import pstats
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from emulators.simulation import Simulation
from emulators.simulation_process import SimulationProcess
from hil.config import load_config
from hil.estimation.apparent_gravity import ApparentGravityEstimator
from hil.estimation.online import OnlineEstimator

CONFIG = "configs/liu2019_sim.yaml"
ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("hil", "drivers", "emulators")


def emulation_and_estimation() -> None:
    simulation = SimulationProcess()  # as hil simulate starts it: it imports the emulator meanwhile
    cfg = load_config(CONFIG)
    sim = Simulation.from_config(cfg)
    t0 = time.perf_counter()
    batches = list(sim.batches())
    t1 = time.perf_counter()
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0 / cfg.estimator.solve_rate_hz)
    for batch in batches:
        est.update_many(batch)
    est.solution()
    t2 = time.perf_counter()
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0 / cfg.estimator.solve_rate_hz)
    with simulation:
        for batch in simulation.batches(cfg):  # as hil simulate runs them: the emulator on the other core, ahead
            est.update_many(batch)
    est.solution()
    t3 = time.perf_counter()
    n = sim.samples
    print(f"samples                         {n}")
    print(f"emulation (truth + errors)      {t1 - t0:.3f} s   {n / (t1 - t0):,.0f} samples/s")
    print(f"estimation ({len(est.snapshots)} solves)          {t2 - t1:.3f} s   {n / (t2 - t1):,.0f} samples/s")
    print(f"emulation + estimation          {t2 - t0:.3f} s   {n / (t2 - t0):,.0f} samples/s (one after the other)")
    print(f"emulation in a child process    {t3 - t2:.3f} s   {n / (t3 - t2):,.0f} samples/s (as hil simulate runs them)")


def profile_top_five() -> None:
    """The five functions with the most own time in emulation + estimation of the scenario."""
    cfg = load_config(CONFIG)
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0 / cfg.estimator.solve_rate_hz)
    profile = cProfile.Profile()
    profile.enable()
    for batch in sim.batches():
        est.update_many(batch)
    profile.disable()
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(5)
    rows = [line for line in text.getvalue().splitlines() if line.strip()[:1].isdigit() and "function calls" not in line]
    print("profile, top five by own time (ncalls tottime percall cumtime percall function):")
    for line in rows[:5]:
        print(f"    {line.strip()}")


def _run(*args: str, out: bool = False, **env: str) -> float:
    """Wall time of one run of ``hil ARGS`` as a subprocess; ``out``: with a fresh ``--out``. The run may write
    bytecode (a shell that sets PYTHONDONTWRITEBYTECODE would otherwise make every run compile the project
    afresh); ``env`` is added to the environment."""
    child = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"} | env
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "hil.cli", *args, *(("--out", tmp) if out else ())], check=True,
                       capture_output=True, env=child)  # fmt: skip
        return time.perf_counter() - t0


def _best_of_3(*args: str, out: bool = False) -> float:
    _run(*args, out=out)  # writes the bytecode the warm runs then find
    return min(_run(*args, out=out) for _ in range(3))


def whole_command() -> None:
    with tempfile.TemporaryDirectory() as tree:  # the project's sources without their bytecode, found first
        for package in PACKAGES:
            shutil.copytree(ROOT / package, Path(tree) / package, ignore=shutil.ignore_patterns("__pycache__"))
        first = _run("simulate", CONFIG, out=True, PYTHONPATH=tree)
    print(f"hil simulate (start-up, figures) {first:.3f} s   first run (the project's modules compiled afresh)")
    with tempfile.TemporaryDirectory() as cache:  # no compiled modules at all: every import compiles
        cold = _run("simulate", CONFIG, out=True, PYTHONPYCACHEPREFIX=cache)
    print(f"hil simulate (start-up, figures) {cold:.3f} s   every module compiled afresh")
    print(f"hil simulate (start-up, figures) {_best_of_3('simulate', CONFIG, out=True):.3f} s   warm, best of 3")
    print(f"hil simulate --no-figures        {_best_of_3('simulate', CONFIG, '--no-figures', out=True):.3f} s"
          "   warm, best of 3")  # fmt: skip
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # KiB on Linux
    print(f"hil simulate peak RSS            {peak:.0f} MiB")
    print(f"hil --help                       {_best_of_3('--help'):.3f} s   best of 3")


def per_sample_cost() -> None:
    rng = np.random.default_rng(0)
    n = 200_000
    t_end = np.arange(1, n + 1) * 0.005
    c = np.tile(np.eye(3), (n, 1, 1))
    z = rng.normal(size=(n, 3))
    est = ApparentGravityEstimator()
    t0 = time.perf_counter()
    for k in range(0, n, 200):  # one second of 200 Hz data per call, as the live pipeline hands it over
        est.update_many(t_end[k : k + 200] - 0.005, t_end[k : k + 200], z[k : k + 200], c[k : k + 200])
    ours = (time.perf_counter() - t0) / n * 1e6
    t0 = time.perf_counter()
    for _ in range(200):
        est.solve()
    solve = (time.perf_counter() - t0) / 200 * 1e6
    print(f"12-state update, per sample      {ours:.2f} us (batches of 200); solve {solve:.0f} us per display update")
    try:
        from filterpy.kalman import KalmanFilter
    except ImportError:
        print("filterpy not installed: pip install -e '.[bench]' to compare")
        return
    kf = KalmanFilter(dim_x=12, dim_z=3)
    kf.P *= 1e6
    kf.R = np.eye(3)
    kf.Q = np.zeros((12, 12))
    h = np.zeros((3, 12))
    m = 20_000
    t0 = time.perf_counter()
    for k in range(m):
        h[:, :3] = h[:, 3:6] = h[:, 6:9] = 0.0
        kf.H = h
        kf.update(z[k])
    theirs = (time.perf_counter() - t0) / m * 1e6
    print(f"filterpy KalmanFilter.update     {theirs:.2f} us per sample   ratio {theirs / ours:.1f}x")


if __name__ == "__main__":
    emulation_and_estimation()
    profile_top_five()
    whole_command()
    per_sample_cost()
