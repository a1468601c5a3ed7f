"""IEEE 952's five terms read back from the emulated static IMU over seeds: every term of the gyros and the
accelerometers resolved, unbiased, and inside its interval as often as the interval's level says.

    .venv/bin/python tests/test_allan_five_terms.py [SEEDS]     # the table, for more seeds than the test's
"""

from __future__ import annotations

import math
import sys

import numpy as np

from emulators.sensor_errors import SensorErrorModel
from hil.config import ImuErrors
from hil.estimation import allan
from hil.estimation.allan_fit import FLICKER_FLOOR, TERM_NAMES
from hil.outputs.noise import SENSORS
from hil.trial.noise_runner import noise_truth
from hil.units import DEG_PER_H, HOUR, SQRT_HOUR, UG

T = 0.01  # s, 100 Hz
SAMPLES = 1 << 16  # 655 s
LEVEL = 0.683
# Each term dominant over part of the octaves: quantisation at 0.01-0.02 s, white to 0.25 s, bias instability
# to 2.5 s, random walk to 20 s, the ramp beyond. The white noise moves the angle by 0.6 quanta a sample, which
# keeps the carried quantisation error white.
WHITE_TO_FLICKER_S, FLICKER_TO_WALK_S, WALK_TO_RAMP_S, STEP_IN_QUANTA = 0.25, 2.5, 20.0, 0.6


def coefficients(white: float) -> tuple[float, float, float, float, float]:
    """Q, N, B, K, R (SI) whose Allan variances cross at the taus above, for a white coefficient N."""
    flicker = white / math.sqrt(FLICKER_FLOOR * WHITE_TO_FLICKER_S)
    walk = math.sqrt(3.0 * FLICKER_FLOOR * flicker**2 / FLICKER_TO_WALK_S)
    ramp = math.sqrt(2.0 * walk**2 / (3.0 * WALK_TO_RAMP_S))
    return white * math.sqrt(T) / STEP_IN_QUANTA / math.sqrt(12.0), white, flicker, walk, ramp


def errors() -> ImuErrors:
    """The emulator's configuration: gyro N 0.017 deg/sqrt(h), accelerometer N 0.03 m/s/sqrt(h)."""
    (qg, ng, bg, kg, rg), (qa, na, ba, ka, ra) = coefficients(5e-6), coefficients(5e-4)
    root_rate = 1.0 / math.sqrt(T)
    return ImuErrors(
        dtheta_quantum_rad=qg * math.sqrt(12.0), gyro_noise_dph=(ng * root_rate / DEG_PER_H,) * 3,
        gyro_bias_instability_dph=(bg / DEG_PER_H,) * 3,
        gyro_random_walk_dph_per_sqrt_h=(kg * SQRT_HOUR / DEG_PER_H,) * 3,
        gyro_drift_dph_per_h=(rg * HOUR / DEG_PER_H,) * 3,
        dv_quantum_mps=qa * math.sqrt(12.0), accel_noise_ug=(na * root_rate / UG,) * 3,
        accel_bias_instability_ug=(ba / UG,) * 3, accel_random_walk_ug_per_sqrt_h=(ka * SQRT_HOUR / UG,) * 3,
        accel_drift_ug_per_h=(ra * HOUR / UG,) * 3,
    )


def read_back(seeds: int) -> dict[str, dict[str, float]]:
    """Per term, the gyros' and accelerometers' pooled over seeds: intervals, resolved, mean fitted / truth and
    coverage."""
    config = errors()
    truth = noise_truth(config, 1.0 / T)
    zeros = np.zeros((SAMPLES, 3))
    records = [SensorErrorModel(config, 1.0 / T, seed).apply(np.arange(1, SAMPLES + 1) * T, zeros, zeros)
               for seed in range(seeds)]
    analyses = [allan.analyse(np.hstack([r[i] for r in records]), T, LEVEL) for i in range(2)]
    out = {}
    for name, keys in zip(TERM_NAMES, zip(*(keys for _, _, keys in SENSORS))):
        fitted = [(t, truth[sensor][key][0] * getattr(units, name))
                  for (sensor, units, _), key, analysis in zip(SENSORS, keys, analyses)
                  for t in getattr(analysis, name)]
        values = [t.value / true for t, true in fitted if t.value is not None]
        out[name] = {"intervals": len(fitted), "resolved": len(values), "ratio": float(np.mean(values)),
                     "coverage": float(np.mean([t.lower <= true <= t.upper for t, true in fitted]))}
    return out


def test_the_five_terms_are_read_back_within_their_intervals_at_their_level():
    """12 seeds x 3 axes x 2 sensors: 72 intervals a term, each term's coverage within 3 binomial standard
    deviations of 68.3 % (0.52-0.85), resolved in three runs of four or more (the ramp, beyond 1.5 standard
    deviations, in 58 of 72), its mean within 5 % of the truth."""
    for name, found in read_back(12).items():
        band = 3.0 * math.sqrt(LEVEL * (1.0 - LEVEL) / found["intervals"])
        assert abs(found["coverage"] - LEVEL) < band, (name, found)
        assert found["resolved"] >= 0.75 * found["intervals"], (name, found)
        assert abs(found["ratio"] - 1.0) < 0.05, (name, found)


if __name__ == "__main__":
    for term, found in read_back(int(sys.argv[1]) if len(sys.argv) > 1 else 12).items():
        print(f"{term:17s} intervals {found['intervals']:4d}  resolved {found['resolved']:4d}  "
              f"mean fitted/truth {found['ratio']:.3f}  coverage {found['coverage']:.3f} (nominal {LEVEL})")
