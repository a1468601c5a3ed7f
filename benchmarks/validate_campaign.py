"""The estimator's consistency over a campaign: 200 runs of the 2019 paper's swing (configs/liu2019_sim.yaml),
600 s at 100 Hz with 50 ug white accelerometer noise, on a LocalCluster. Prints std(error)/mean(sigma) per
axis with its 95 % band, the mean NEES with its chi-square band, and PASS when the ratio is within
[0.85, 1.15] on every axis and the NEES mean inside its band (exit 1 otherwise).

    .venv/bin/python benchmarks/validate_campaign.py [--runs 200] [--workers 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import yaml

from hil.campaign.runner import run_campaign

RATIO_LIMITS = (0.85, 1.15)
BASE = Path(__file__).resolve().parent.parent / "configs" / "liu2019_sim.yaml"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--workers", type=int)
    parser.add_argument("--out", type=Path, help="keep the campaign's outputs here (default: a temporary directory)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "campaign"
        spec = Path(tmp) / "validate.yaml"
        spec.write_text(yaml.safe_dump({"base": str(BASE), "runs": args.runs, "seed": 2019, "sweep": {
            "trial.duration_s": [600.0], "trial.rate_hz": [100.0], "imu.errors.accel_noise_ug": [[50.0, 50.0, 50.0]]}}))
        start = time.perf_counter()
        code = run_campaign(spec, out, workers=args.workers)
        wall = time.perf_counter() - start
        summary = json.loads((out / "summary.json").read_text())
    point = summary["points"][0]
    ratio_ok = all(RATIO_LIMITS[0] <= r <= RATIO_LIMITS[1] for r in point["ratio"])
    print(f"{point['with_estimate']} runs with an estimate, {summary['failed']} failed, {wall:.0f} s on "
          f"{summary['cluster']['workers']} workers")
    print("error mean (ug):      " + " ".join(f"{v:8.3f}" for v in point["error_mean_ug"]))
    print("error std (ug):       " + " ".join(f"{v:8.3f}" for v in point["error_std_ug"]))
    print("mean sigma (ug):      " + " ".join(f"{v:8.3f}" for v in point["sigma_mean_ug"]))
    print("std(error)/mean(sigma): " + " ".join(f"{v:.3f}" for v in point["ratio"])
          + f"  (95 % band {point['ratio_band'][0]:.3f}-{point['ratio_band'][1]:.3f}; limits {RATIO_LIMITS})")
    print(f"NEES mean: {point['nees_mean']:.3f}  (95 % chi-square band {point['nees_band'][0]:.3f}-"
          f"{point['nees_band'][1]:.3f})")
    passed = code == 0 and ratio_ok and point["nees_inside"]
    print("PASS" if passed else "FAIL")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
