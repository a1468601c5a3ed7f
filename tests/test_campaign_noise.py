"""Campaigns of kind ``noise`` (and the SPEC's kind): the noise terms a config puts in against an independent
derivation of the emulator's processes' Allan variance, the coverage statistics on hand-made rows, and a small
noise campaign on a LocalCluster of 2 worker processes."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from hil.campaign.noise_summary import coverage_band, point_lines, point_summary
from hil.campaign.runner import resumed_rows, run_campaign
from hil.campaign.spec import CampaignSpec, SpecError, load_campaign
from hil.config import ImuErrors
from hil.estimation.allan import ACCEL_UNITS, GYRO_UNITS
from hil.estimation.allan_fit import FLICKER_FLOOR
from hil.trial.noise_runner import noise_truth
from hil.units import DEG_PER_H, HOUR, UG

ROOT = Path(__file__).resolve().parent.parent
STATIC = ROOT / "configs" / "noise_static.yaml"
# emulators.sensor_errors.BiasInstability's process as its docstring defines it: Gauss-Markov processes of
# correlation times 0.1 s * 4^i, i = -2..11, each of variance B^2 ln(4) / pi
CORRELATION_TIMES = 0.1 * 4.0 ** np.arange(-2, 12)


def _spec(tmp_path: Path, **keys) -> Path:
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"base": str(STATIC), "runs": 2, "seed": 3, **keys}))
    return path


def test_kind_defaults_to_swing_and_a_swing_specs_summary_entry_is_as_before(tmp_path):
    assert load_campaign(_spec(tmp_path)).spec.kind == "swing"
    assert load_campaign(_spec(tmp_path, kind="noise")).spec.kind == "noise"
    swing = CampaignSpec(base="b.yaml", runs=2, kind="swing")
    assert swing.as_dict() == {"base": "b.yaml", "runs": 2, "seed": 0, "sweep": {}}
    assert CampaignSpec(base="b.yaml", runs=2, kind="noise").as_dict()["kind"] == "noise"


def test_an_unknown_kind_names_the_key_in_one_line(tmp_path):
    with pytest.raises(SpecError, match=r"kind: Input should be 'swing', 'noise' or 'calibration'"):
        load_campaign(_spec(tmp_path, kind="allan"))
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "campaign", str(_spec(tmp_path, kind="allan")),
                           "--out", "o"], check=False, cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "kind: Input should be 'swing', 'noise' or 'calibration'" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_resume_refuses_the_runs_of_a_campaign_of_another_kind(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    swing = _spec(tmp_path)
    (out / "campaign.yaml").write_text(swing.read_text())
    noise = load_campaign(_spec(tmp_path, kind="noise"))
    with pytest.raises(SpecError, match="the runs in .* are of kind swing, .* of kind noise"):
        resumed_rows(noise, out)
    (out / "campaign.yaml").write_text(_spec(tmp_path, kind="noise").read_text())
    assert resumed_rows(noise, out) == []  # no runs.parquet yet


def _boxcar(m: int, d: np.ndarray) -> np.ndarray:
    """Autocorrelation of a length-m boxcar of height 1/m at lags d."""
    return np.clip(m - np.abs(d), 0, None) / m**2


def exact_avar(autocovariance, m: int) -> float:
    """Allan variance at tau = m T of a stationary rate sequence, from its autocovariance R(d): half the
    variance of the difference of two adjacent m-means, 1/2 sum_d R(d) a(d) with a the autocorrelation of
    the difference weights w = (-1/m, ..., +1/m, ...): a(d) = 2 B(d) - B(d - m) - B(d + m), B the boxcar's."""
    d = np.arange(-2 * m + 1, 2 * m)
    a = 2.0 * _boxcar(m, d) - _boxcar(m, d - m) - _boxcar(m, d + m)
    return 0.5 * float(np.sum(autocovariance(d) * a))


def test_exact_avar_weights_are_the_difference_of_two_means():
    m = 5
    w = np.concatenate([-np.ones(m), np.ones(m)]) / m
    d = np.arange(-2 * m + 1, 2 * m)
    np.testing.assert_allclose(2.0 * _boxcar(m, d) - _boxcar(m, d - m) - _boxcar(m, d + m),
                               np.correlate(w, w, "full"), atol=1e-15)


def test_white_noise_truth_is_the_allan_coefficient_of_a_white_sequence():
    rate = 100.0
    errors = ImuErrors(gyro_noise_dph=(10.5032, 5.0, 1.0), accel_noise_ug=(420.129, 100.0, 10.0))
    truth = noise_truth(errors, rate)
    for sensor, sigma, units, key in (("gyro", np.array(errors.gyro_noise_dph) * DEG_PER_H, GYRO_UNITS,
                                       "arw_deg_per_sqrt_h"),
                                      ("accel", np.array(errors.accel_noise_ug) * UG, ACCEL_UNITS,
                                       "vrw_m_per_s_per_sqrt_h")):
        for k in range(3):
            for m in (1, 8, 1024):  # avar of independent samples: sigma^2 / m, i.e. N^2 / tau
                avar = exact_avar(lambda d, s=sigma[k]: np.where(d == 0, s**2, 0.0), m)
                assert truth[sensor][key][k] * units.white == pytest.approx(math.sqrt(avar * m / rate), rel=1e-12)
    # the datasheet figures that configs/noise_static.yaml gives for its per-sample sigmas
    assert truth["gyro"]["arw_deg_per_sqrt_h"][0] == pytest.approx(0.0175, abs=5e-5)
    assert truth["accel"]["vrw_m_per_s_per_sqrt_h"][0] == pytest.approx(0.0247, abs=5e-5)


def test_bias_instability_truth_is_the_floor_of_the_emulators_gauss_markov_sum():
    rate, b = 100.0, (0.5, 2.0, 20.0)
    truth = noise_truth(ImuErrors(gyro_bias_instability_dph=b, accel_bias_instability_ug=b), rate)
    phi = np.exp(-1.0 / rate / CORRELATION_TIMES)

    def autocovariance(d):  # of the process for B = 1 (its Allan deviation scales with B)
        return math.log(4.0) / math.pi * np.sum(phi[:, None] ** np.abs(d)[None, :], axis=0)

    floors = [math.sqrt(exact_avar(autocovariance, round(tau * rate)) / FLICKER_FLOOR)
              for tau in (1.28, 10.24, 163.84, 1310.72)]
    assert floors == pytest.approx([1.0] * 4, rel=0.02)
    for k in range(3):
        assert truth["gyro"]["bias_instability_dph"][k] * GYRO_UNITS.bias_instability == pytest.approx(
            b[k] * DEG_PER_H, rel=1e-12)
        assert truth["accel"]["bias_instability_ug"][k] * ACCEL_UNITS.bias_instability == pytest.approx(
            b[k] * UG, rel=1e-12)


def test_random_walk_truth_is_the_coefficient_of_the_emulators_wiener_bias():
    """r[k] = r[k-1] + q sqrt(T) n[k]: the difference of two adjacent m-means is sum_i c_i q sqrt(T) n_i with
    c_i the tail sums of the weights (i/m rising, then falling), so avar = q^2 T sum c^2 / 2 -> q^2 tau / 3."""
    rate, m = 100.0, 4096
    q = np.array([2.0, 1.0, 0.5])
    truth = noise_truth(ImuErrors(gyro_random_walk_dph_per_sqrt_h=tuple(q), accel_random_walk_ug_per_sqrt_h=tuple(q)),
                        rate)
    c = np.concatenate([np.arange(m), 2 * m - np.arange(m, 2 * m)]) / m
    for k in range(3):
        for sensor, key, unit, units in (("gyro", "rrw_deg_per_h_per_sqrt_h", DEG_PER_H, GYRO_UNITS),
                                         ("accel", "rrw_m_per_s2_per_sqrt_h", UG, ACCEL_UNITS)):
            q_si = q[k] * unit / math.sqrt(HOUR)
            avar = 0.5 * q_si**2 / rate * np.sum(c**2)
            k_fit = math.sqrt(3.0 * avar / (m / rate))
            assert truth[sensor][key][k] * units.random_walk == pytest.approx(k_fit, rel=1e-3)


def _binomial_band(n: int, p: float) -> tuple[float, float]:
    """The 2.5 % and 97.5 % quantiles of Binomial(n, p) over n, summed from the probability mass."""
    cdf = np.cumsum([math.comb(n, k) * p**k * (1 - p) ** (n - k) for k in range(n + 1)])
    return int(np.argmax(cdf >= 0.025)) / n, int(np.argmax(cdf >= 0.975)) / n


def _row(run: int, value: float | None, lower: float | None, upper: float | None, truth: float = 2.0) -> dict:
    key = "gyro.arw_deg_per_sqrt_h"
    return {"id": f"p000-r{run:04d}", "point": 0, "run": run, "seed": run, "error": None, "ci.level": 0.683,
            f"{key}.0": value, f"ci.{key}.lower.0": lower, f"ci.{key}.upper.0": upper, f"truth.{key}.0": truth,
            "accel.vrw_m_per_s_per_sqrt_h.0": 0.1, "truth.accel.vrw_m_per_s_per_sqrt_h.0": 0.0}


def test_coverage_statistics_of_hand_made_rows():
    values = [1.8, 2.1, 2.4, 1.9, 2.0, 2.2, 2.6, 1.5, 2.3]
    rows = [_row(i, v, v - 0.25, v + 0.25) for i, v in enumerate(values)]  # holds 2.0 unless |v - 2| > 0.25
    rows += [_row(9, None, None, None), {"id": "p000-r0010", "point": 0, "run": 10, "seed": 10, "error": "boom"}]
    rows.append(_row(11, None, 0.0, 2.1))  # unresolved, its upper limit holding the truth: counts in the coverage
    p = point_summary(0, {"trial.duration_s": 60}, rows)
    arw = p["terms"]["gyro.arw_deg_per_sqrt_h"][0]
    assert (p["runs"], p["failed"], p["done"], p["ci_level"]) == (12, 1, 11, 0.683)
    assert (arw["resolved"], arw["unresolved"], arw["intervals"], arw["covered"]) == (9, 2, 10, 6)
    assert arw["coverage"] == pytest.approx(6 / 10)
    assert arw["mean"] == pytest.approx(np.mean(values)) and arw["std"] == pytest.approx(np.std(values, ddof=1))
    assert arw["relative_error_mean"] == pytest.approx(np.mean(values) / 2.0 - 1.0)
    assert arw["coverage_band"] == pytest.approx(_binomial_band(10, 0.683))
    assert arw["coverage_inside"] and p["coverage_consistent"] and p["coverage_tested"] == 1
    vrw = p["terms"]["accel.vrw_m_per_s_per_sqrt_h"][0]
    assert vrw == {"truth": 0.0, "resolved": 11, "unresolved": 0}  # not configured: a count, no statistics
    assert "consistent with their level on all 1 terms" in point_lines(p)[0]

    narrow = [_row(i, 2.0 + 0.1 * (-1) ** i, 2.0 + 0.1 * (-1) ** i - 0.05, 2.0 + 0.1 * (-1) ** i + 0.05)
              for i in range(40)]
    narrow[0] = _row(0, 2.0, 1.9, 2.1)
    p = point_summary(0, {}, narrow)
    arw = p["terms"]["gyro.arw_deg_per_sqrt_h"][0]
    assert arw["coverage"] == 1 / 40 and arw["coverage_band"] == pytest.approx(_binomial_band(40, 0.683))
    assert not p["coverage_consistent"] and (p["coverage_above"], p["coverage_below"]) == (0, 1)
    assert "NOT consistent" in point_lines(p)[0] and "1 below (too narrow)" in point_lines(p)[0]


def test_coverage_band_holds_95_percent_of_binomial_counts():
    rng = np.random.default_rng(4)
    for n, p in ((20, 0.683), (200, 0.683), (50, 0.95)):
        low, high = coverage_band(n, p)
        counts = rng.binomial(n, p, 20000) / n
        assert np.mean((counts >= low) & (counts <= high)) >= 0.95


def test_a_noise_campaign_on_a_local_cluster_of_two_workers(tmp_path, capsys):
    spec = _spec(tmp_path, kind="noise", runs=3, sweep={"trial.duration_s": [120.0],
                                                        "imu.errors.accel_noise_ug": [[100] * 3, [400] * 3]})
    assert run_campaign(spec, tmp_path / "o", workers=2) == 0
    table = pq.read_table(tmp_path / "o" / "runs.parquet")
    assert table.num_rows == 6 and table.column("error").null_count == 6
    assert table.column("truth.accel.vrw_m_per_s_per_sqrt_h.0").to_pylist() == pytest.approx(
        [100 * UG * 0.1 * 60] * 3 + [400 * UG * 0.1 * 60] * 3)
    assert set(table.column("source").to_pylist()) == {"simulation"}
    assert table.column("samples").to_pylist() == [12000] * 6
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["spec"]["kind"] == "noise" and summary["runs"] == 6 and summary["failed"] == 0
    for p in summary["points"]:
        vrw = p["terms"]["accel.vrw_m_per_s_per_sqrt_h"]
        assert all(a["resolved"] == 3 and abs(a["relative_error_mean"]) < 0.05 for a in vrw)
        inside = [a["coverage_inside"] for axes in p["terms"].values() for a in axes if "coverage_inside" in a]
        assert p["coverage_tested"] == len(inside) > 0  # the flag recounted from the point's terms
        assert p["coverage_consistent"] == all(inside) and p["coverage_above"] + p["coverage_below"] == inside.count(False)
    page = (tmp_path / "o" / "campaign.html").read_text()
    assert "Noise terms per sweep point" in page and page.count("data:image/png;base64,") >= 3
    out = capsys.readouterr().out
    assert "campaign: 6 runs, 0 failed, on 2 workers" in out and "accel.vrw_m_per_s_per_sqrt_h (truth" in out


def test_the_shipped_noise_example_sweeps_accel_noise_and_duration_of_the_static_record():
    campaign = load_campaign(ROOT / "configs" / "campaign_noise.yaml")
    assert campaign.spec.kind == "noise" and len(campaign.points) == 4
    assert {tuple(p) for p in campaign.points} == {("imu.errors.accel_noise_ug", "trial.duration_s")}
    assert campaign.tasks[0].config["turntable"]["motion"] == {"kind": "static"}
