"""The 2018 gravity-vector paper's bias model on the 2019 paper's swing: an 8 h trial at 100 Hz with bias
[60, 150, 260] ug, drift [2, -1.5, 3] ug/h and 50 ug white noise, over seeds; prints the drift error
against its reported sigma, the RMS error, and the drift check of the constant model with and without
the drift.

    .venv/bin/python benchmarks/validate_drift.py [--seeds 5] [--hours 8]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from emulators.simulation import Simulation
from hil.config import parse_config
from hil.estimation.online import OnlineEstimator
from hil.units import HOUR, UG

SWING = {"outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
         "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
         "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6}}
DRIFT = np.array([2.0, -1.5, 3.0])  # ug/h


def trial(seed: int, hours: float, drift: np.ndarray, bias_model: str):
    cfg = parse_config({
        "trial": {"name": "drift", "duration_s": hours * HOUR, "rate_hz": 100.0, "seed": seed},
        "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
        "turntable": {"motion": {"kind": "swing", "axes": SWING}},
        "imu": {"errors": {"accel_bias_ug": [60, 150, 260], "accel_noise_ug": [50, 50, 50],
                           "accel_drift_ug_per_h": list(drift)}},
    })
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=600.0, bias_model=bias_model)
    for batch in sim.batches(chunk=100_000):
        est.update_many(batch)
    return est.solution()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--hours", type=float, default=8.0)
    args = parser.parse_args()
    errors = []
    started = time.perf_counter()
    for seed in range(1, args.seeds + 1):
        final = trial(seed, args.hours, DRIFT, "drift").full
        k, sigma = final.drift / UG * HOUR, final.drift_sigma / UG * HOUR
        errors.append(k - DRIFT)
        ratio = np.abs(k - DRIFT) / sigma
        print(f"seed {seed}: drift {np.array2string(k, precision=3)} ug/h, error/sigma "
              f"{np.array2string(ratio, precision=2)}, sigma {np.array2string(sigma, precision=3)} ug/h")
    errors = np.array(errors)
    print(f"drift error RMS per axis {np.array2string(np.sqrt(np.mean(errors**2, axis=0)), precision=3)} ug/h "
          f"(target <= 0.2)")
    for drift, name in ((DRIFT, "with drift"), (np.zeros(3), "without drift")):
        check = trial(1, args.hours, drift, "constant").drift_check
        print(f"constant model {name}: drift_check significant = {check.significant}, drift "
              f"{np.array2string(check.drift / UG * HOUR, precision=3)} ug/h")
    print(f"{time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
