"""Noise terms recovered from an emulated static trial: 8 h at 100 Hz, every term, several seeds.

    .venv/bin/python benchmarks/validate_noise.py [--seeds 5] [--hours 8] [--level 0.95] [--quiet]
    .venv/bin/python benchmarks/validate_noise.py --seeds 100 --hours 1 --level 0.683 --quiet  # coverage
Gyros and accelerometers carry white noise, bias instability and random walk, set so that white
dominates below 10 s, bias instability from 10 s to 300 s and random walk above. Prints per seed and
axis each configured term beside the fitted one with its interval (95 % unless --level) and the relative
error (not with --quiet), then the worst error per term against the targets (white 10 %, bias instability
20 %, random walk 30 %), the coverage of the intervals (the resolved ones holding the configured value)
against the binomial 95 % band of their level, and the runtime.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from emulators.sensor_errors import SensorErrorModel
from hil.campaign.noise_summary import coverage_band
from hil.config import ImuErrors
from hil.estimation.allan import ACCEL_UNITS, GYRO_UNITS, AllanAnalysis, TermUnits, analyse
from hil.estimation.allan_fit import FLICKER_FLOOR
from hil.units import DEG_PER_H, UG

RATE_HZ = 100.0
CHUNK = 1 << 18
WHITE_TO_FLICKER_S, FLICKER_TO_WALK_S = 10.0, 300.0
TARGETS = {"white": 0.10, "bias_instability": 0.20, "random_walk": 0.30}


def configured(floor: float) -> dict[str, float]:
    """N, B, K (SI) whose Allan variances cross at the two tau above, for a bias instability B."""
    flicker_avar = FLICKER_FLOOR * floor**2
    return {
        "white": math.sqrt(flicker_avar * WHITE_TO_FLICKER_S),
        "bias_instability": floor,
        "random_walk": math.sqrt(3.0 * flicker_avar / FLICKER_TO_WALK_S),
    }


GYRO = configured(0.5 * DEG_PER_H)
ACCEL = configured(20.0 * UG)


def errors() -> ImuErrors:
    """The ImuErrors of GYRO and ACCEL: white noise as the per-sample sigma N sqrt(rate)."""
    root_rate, root_hour = math.sqrt(RATE_HZ), math.sqrt(3600.0)
    return ImuErrors(
        gyro_noise_dph=(GYRO["white"] * root_rate / DEG_PER_H,) * 3,
        gyro_bias_instability_dph=(GYRO["bias_instability"] / DEG_PER_H,) * 3,
        gyro_random_walk_dph_per_sqrt_h=(GYRO["random_walk"] * root_hour / DEG_PER_H,) * 3,
        accel_noise_ug=(ACCEL["white"] * root_rate / UG,) * 3,
        accel_bias_instability_ug=(ACCEL["bias_instability"] / UG,) * 3,
        accel_random_walk_ug_per_sqrt_h=(ACCEL["random_walk"] * root_hour / UG,) * 3,
    )


def static_trial(seed: int, hours: float) -> tuple[np.ndarray, np.ndarray]:
    """Measured increments (n, 3) of gyros and accelerometers at rest with no motion."""
    model = SensorErrorModel(errors(), RATE_HZ, seed)
    n = int(hours * 3600.0 * RATE_HZ)
    dtheta, dv = np.empty((n, 3)), np.empty((n, 3))
    for start in range(0, n, CHUNK):
        stop = min(n, start + CHUNK)
        zeros = np.zeros((stop - start, 3))
        dtheta[start:stop], dv[start:stop] = model.apply(np.arange(start + 1, stop + 1) / RATE_HZ, zeros, zeros)
    return dtheta, dv


def report(name: str, analysis: AllanAnalysis, truth: dict[str, float], units: TermUnits,
           quiet: bool) -> dict[str, list]:
    """Prints configured vs fitted per term and axis (unless quiet); returns (relative error, inside
    interval) per term: error None for an unresolved term, both None for one without an interval."""
    out: dict[str, list] = {}
    for term, value in truth.items():
        unit = getattr(units, term)
        for axis, fitted in enumerate(getattr(analysis, term)):
            inside = None if fitted.upper is None else fitted.lower <= value <= fitted.upper
            if fitted.value is None:
                if not quiet:
                    limit = "" if fitted.upper is None else f" [{fitted.lower / unit:.5g}, {fitted.upper / unit:.5g}]"
                    print(f"  {name} {term:16s} {'xyz'[axis]}: configured {value / unit:.5g}, fitted null{limit}")
                out.setdefault(term, []).append((None, inside))
                continue
            error = fitted.value / value - 1.0
            if not quiet:
                print(f"  {name} {term:16s} {'xyz'[axis]}: configured {value / unit:.5g}, fitted "
                      f"{fitted.value / unit:.5g} [{fitted.lower / unit:.5g}, {fitted.upper / unit:.5g}] {error:+.1%}"
                      f"{'' if inside else '  OUTSIDE'}")
            out.setdefault(term, []).append((error, inside))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--hours", type=float, default=8.0)
    parser.add_argument("--level", type=float, default=0.95, help="two-sided level of the intervals")
    parser.add_argument("--quiet", action="store_true", help="only the summary")
    args = parser.parse_args()
    print(
        "units: gyro deg/sqrt(h), deg/h, deg/h/sqrt(h); accel m/s/sqrt(h), ug, m/s^2/sqrt(h);"
        f" {args.hours:g} h at {RATE_HZ:g} Hz, intervals at {args.level:.1%}"
    )
    results: dict[str, list] = {}
    t0 = time.perf_counter()
    simulate = analysis_time = 0.0
    for seed in range(1, args.seeds + 1):
        t1 = time.perf_counter()
        dtheta, dv = static_trial(seed, args.hours)
        t2 = time.perf_counter()
        gyro, accel = (analyse(x, 1.0 / RATE_HZ, args.level) for x in (dtheta, dv))
        simulate, analysis_time = simulate + t2 - t1, analysis_time + time.perf_counter() - t2
        if not args.quiet:
            print(f"seed {seed}:")
        for name, analysis, truth, units in (("gyro ", gyro, GYRO, GYRO_UNITS), ("accel", accel, ACCEL, ACCEL_UNITS)):
            for term, rows in report(name, analysis, truth, units, args.quiet).items():
                results.setdefault(f"{name.strip()} {term}", []).extend(rows)
    print(f"summary over seeds and axes (the binomial 95 % band of coverage at the level {args.level:.1%}):")
    for key, rows in results.items():
        errors = [abs(e) for e, _ in rows if e is not None]
        bounded = [i for _, i in rows if i is not None]
        worst = max(errors, default=math.inf)
        target = TARGETS[key.split(" ", 1)[1]]
        low, high = coverage_band(len(bounded), args.level) if bounded else (math.nan, math.nan)
        coverage = sum(bounded) / len(bounded) if bounded else math.nan
        verdict = "ok" if worst <= target and low <= coverage <= high else "FAILS"
        print(f"  {key:24s} worst {worst:.1%} (target {target:.0%}), {len(rows) - len(errors)} unresolved, "
              f"coverage {sum(bounded)}/{len(bounded)} = {coverage:.3f} (band {low:.3f}-{high:.3f}): {verdict}")
    print(
        f"runtime {time.perf_counter() - t0:.1f} s: emulation {simulate:.1f} s, analysis {analysis_time:.1f} s"
        f" ({analysis_time / (2 * args.seeds):.2f} s per sensor triad)"
    )


if __name__ == "__main__":
    main()
