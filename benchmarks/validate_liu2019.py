"""Accuracy on the 2019 paper's scenario (Tables 1-2) over several seeds.

    .venv/bin/python benchmarks/validate_liu2019.py [--seeds 5]
Prints the bias error RMS over seeds per axis at 500 s and at 4000 s (targets: <= 10 ug and <= 1 ug),
the mean 1-sigma the estimator reports, the Gram rank, and the method-1/method-2/theoretical level
alignment errors beside the paper's Table 3, with gyro errors on and off.
"""

from __future__ import annotations

import argparse

import numpy as np

from emulators.simulation import Simulation
from hil.config import load_config
from hil.estimation.online import OnlineEstimator
from hil.units import DEG, UG

TABLE3 = {"theoretical": (0.008594, -0.003437), "method1": (0.008687, -0.003398), "method2": (0.000069, -0.000218)}


def run(seed: int, gyro: bool) -> tuple[dict[float, np.ndarray], np.ndarray, object]:
    cfg = load_config("configs/liu2019_sim.yaml")
    errors = cfg.imu.errors
    if not gyro:
        errors = errors.model_copy(update={"gyro_bias_dph": (0.0,) * 3, "gyro_noise_dph": (0.0,) * 3})
    cfg = cfg.model_copy(
        update={"trial": cfg.trial.model_copy(update={"seed": seed}), "imu": cfg.imu.model_copy(update={"errors": errors})}
    )
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=100.0)
    for batch in sim.batches():
        est.update_many(batch)
    truth = np.array(cfg.imu.errors.accel_bias_ug)
    at = {s.t: s.full.bias / UG - truth for s in est.snapshots if s.t in (500.0, 4000.0)}
    tail = [s for s in est.snapshots if s.t >= 3500.0]
    levels = np.array([[*s.error_method1[:2], *s.error_method2[:2], *s.error_theoretical] for s in tail]).mean(axis=0)
    return at, levels / DEG, est.snapshots[-1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    for gyro in (True, False):
        errors = {500.0: [], 4000.0: []}
        levels, sigmas = [], []
        for seed in range(1, args.seeds + 1):
            at, level, final = run(seed, gyro)
            for t in errors:
                errors[t].append(at[t])
            levels.append(level)
            sigmas.append(final.full.bias_sigma / UG)
        print(f"gyro errors {'on' if gyro else 'off'}, {args.seeds} seeds")
        for t, e in errors.items():
            rms = np.sqrt(np.mean(np.square(e), axis=0))
            print(f"  bias error RMS at {t:6.0f} s (ug): x {rms[0]:.3f}  y {rms[1]:.3f}  z {rms[2]:.3f}")
        print("  reported 1-sigma at 4000 s (ug): " + "  ".join(f"{v:.3f}" for v in np.mean(sigmas, axis=0)))
        print(f"  Gram rank at 4000 s: {final.full.observability.rank}")
        mean = np.mean(levels, axis=0)
        print("  level errors 3500-4000 s (deg)   pitch      roll     | paper Table 3")
        for name, k in (("method1", 0), ("method2", 2), ("theoretical", 4)):
            paper = TABLE3[name]
            print(f"    {name:12s}                 {mean[k]:+.6f} {mean[k + 1]:+.6f} | {paper[0]:+.6f} {paper[1]:+.6f}")


if __name__ == "__main__":
    main()
