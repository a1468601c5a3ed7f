"""Records with gaps: the differences that span a gap left out and counted, the terms as without gaps, the
missing samples in noise.json, and a record mostly gaps refused."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from emulators.sensor_errors import SensorErrorModel
from hil.cli import main
from hil.config import ImuErrors
from hil.estimation import allan
from hil.units import DEG_PER_H

T = 0.01
B_DPH, SIGMA_DPH = 0.5, 2.0  # bias instability, white rate noise per sample


def _gaps(n: int, fraction: float, seed: int) -> np.ndarray:
    """A mask of n samples, True where missing: gaps of 1-100 samples at random places, ``fraction`` of n."""
    rng = np.random.default_rng(seed)
    missing = np.zeros(n, dtype=bool)
    while missing.sum() < fraction * n:
        start, length = rng.integers(0, n - 100), rng.integers(1, 101)
        missing[start : start + length] = True
    return missing


def test_differences_spanning_a_gap_are_left_out_and_counted():
    """A white record with its middle sample missing: the variance is the mean over the differences that do
    not touch it, and the count says how many (the M of the EDF)."""
    rng = np.random.default_rng(1)
    dx = rng.standard_normal((65, 1))
    gapped = dx.copy()
    gapped[32] = np.nan
    factors = np.array([1, 4, 16])
    avar, counts = allan.overlapping_avar(gapped, 1.0, factors)
    x = np.concatenate([[0.0], np.cumsum(dx[:, 0] - dx[np.arange(65) != 32, 0].mean())])
    for j, m in enumerate(factors):
        kept = [i for i in range(66 - 2 * m) if not i <= 32 < i + 2 * m]  # difference i uses dx[i .. i+2m-1]
        assert counts[j] == len(kept) == 66 - 2 * m - 2 * m
        d = np.array([x[i + 2 * m] - 2 * x[i + m] + x[i] for i in kept])
        assert avar[j, 0] == pytest.approx(np.mean(d * d) / (2.0 * m * m), rel=1e-12)


def test_one_percent_in_gaps_gives_the_terms_of_the_gap_free_record():
    n = 1 << 18
    zeros = np.zeros((n, 3))
    dtheta, _ = SensorErrorModel(ImuErrors(gyro_bias_instability_dph=[B_DPH] * 3, gyro_noise_dph=[SIGMA_DPH] * 3),
                                 1.0 / T, 5).apply(np.arange(1, n + 1) * T, zeros, zeros)
    missing = _gaps(n, 0.01, seed=6)
    gapped = np.where(missing[:, None], np.nan, dtheta)
    arw, b = SIGMA_DPH * DEG_PER_H * math.sqrt(T), B_DPH * DEG_PER_H
    for increments in (dtheta, gapped):
        result = allan.analyse(increments, T, level=0.999)
        assert result.missing == (missing.sum() if increments is gapped else 0)
        for white, flicker in zip(result.white, result.bias_instability):
            assert white.value == pytest.approx(arw, rel=0.01) and white.lower <= arw <= white.upper
            assert flicker.value == pytest.approx(b, rel=0.1) and flicker.lower <= b <= flicker.upper


def test_hil_noise_counts_the_missing_samples_of_a_csv(tmp_path):
    n = 20_000
    rng = np.random.default_rng(3)
    missing = _gaps(n, 0.01, seed=4)
    rows = ["t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps"]
    for k in np.flatnonzero(~missing):
        d = rng.standard_normal(6) * 1e-6
        rows.append(f"{(k + 1) * T:.2f},{d[0]},{d[1]},{d[2]},{d[3]},{d[4]},{9.8 * T + d[5]}")
    path = tmp_path / "gaps.csv"
    path.write_text("\n".join(rows) + "\n")
    assert main(["noise", str(path), "--out", str(tmp_path / "out"), "--no-figures", "--taus", "decade"]) == 0
    doc = json.loads((tmp_path / "out" / "noise.json").read_text())
    assert doc["missing"] == int(missing.sum()) and doc["samples"] == n - int(missing.sum())
    assert doc["tau_s"][:4] == pytest.approx([0.01, 0.02, 0.05, 0.1])


def test_a_record_mostly_gaps_is_refused_in_one_line(tmp_path, capsys):
    increments = np.random.default_rng(2).standard_normal((4096, 3))
    increments[_gaps(4096, 0.15, seed=1)] = np.nan
    with pytest.raises(ValueError, match=r"missing in gaps, more than the 10% the analysis takes"):
        allan.analyse(increments, T)
    assert main(["noise", "configs/noise_static.yaml", "--taus", "hourly", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
