"""campaign.html as a lab sees it in a 1400 px window: every column of each kind's table in sight, and the
statistic that puts a sweep point outside its band marked."""

from __future__ import annotations

import re

import numpy as np
import pytest
from pages import WINDOW_PX, measure, needs_chromium
from test_campaign_calibration import _row as calibration_row

from hil.campaign import calibration_summary, noise_summary
from hil.campaign.calibration_consistency import calibration_section
from hil.campaign.campaign_report import write_campaign_report
from hil.campaign.noise_consistency import noise_section
from hil.campaign.runs import flatten
from hil.campaign.swing_summary import summarise

TRUTH = [60.0, 150.0, 260.0]
SIGMA = np.array([2.4, 5.4, 3.7])  # µg: a 300 s swing's
OPTIMISTIC = 2  # the point whose reported sigma is 1.6 times too small


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """The page of the shipped example's sweep (amplitude 5, 13 deg by 300, 600 s), 20 runs a point."""
    rng = np.random.default_rng(3)
    points = [{"turntable.motion.axes.inner.amplitude_deg": a, "trial.duration_s": d} for a in (5, 13) for d in (300, 600)]
    rows = []
    for p in range(len(points)):
        sigma = SIGMA * (1 + p)
        for k in range(20):
            errors = rng.normal(0.0, sigma * (1.6 if p == OPTIMISTIC else 1.0))
            rows.append({"id": f"p{p:03d}-r{k:04d}", "point": p, "run": k, "seed": k, "error": None,
                         **flatten({"estimate": {"accel_bias_ug": list(TRUTH + errors), "accel_bias_sigma_ug": list(sigma),
                                                 "bias_model": "constant", "converged_at_s": 100.0 + 10 * k},
                                    "truth": {"accel_bias_ug": TRUTH}})})  # fmt: skip
    summary = summarise(points, rows, {"scheduler": "tcp://127.0.0.1:8786", "workers": 2})
    return write_campaign_report(tmp_path_factory.mktemp("campaign"), summary, rows), summary


CLUSTER = {"scheduler": "tcp://127.0.0.1:8786", "workers": 2}
NOISE_TERMS = {"gyro.arw_deg_per_sqrt_h": 0.0123, "gyro.bias_instability_dph": 0.0512,
               "accel.vrw_m_per_s_per_sqrt_h": 0.00294}
CALIBRATION_TERMS = ([f"accel.bias_ug.{k}" for k in range(3)] + [f"gyro.scale_ppm.{k}" for k in range(3)]
                     + [f"accel.misalignment_arcsec.{k}" for k in range(6)])


def _noise_row(rng, point: int, run: int) -> dict:
    """A noise run's row: each term near its truth, with a 68.3 % interval of 7 %."""
    row = {"id": f"p{point:03d}-r{run:04d}", "point": point, "run": run, "seed": run, "error": None, "ci.level": 0.683}
    for term, truth in NOISE_TERMS.items():
        for k in range(3):
            value = truth * (1 + 0.05 * rng.normal())
            row.update({f"{term}.{k}": value, f"ci.{term}.lower.{k}": 0.93 * value, f"ci.{term}.upper.{k}": 1.07 * value,
                        f"truth.{term}.{k}": truth})  # fmt: skip
    return row


def _kind_page(out, kind, points: list[dict], rows: list[dict]):
    """campaign.html of a noise or calibration campaign of these rows."""
    summary_of, section = {"noise": (noise_summary.point_summary, noise_section),
                           "calibration": (calibration_summary.point_summary, calibration_section)}[kind]
    summary = {"points": [summary_of(k, values, [r for r in rows if r["point"] == k]) for k, values in enumerate(points)],
               "runs": len(rows), "failed": 0, "cluster": CLUSTER}  # fmt: skip
    return write_campaign_report(out, summary, rows, section)


@needs_chromium
def test_every_column_of_the_campaign_table_is_in_sight_at_1400_px(page, tmp_path):
    path, _ = page
    assert measure(path, tmp_path) == {"width": pytest.approx(WINDOW_PX, abs=20), "clipped": []}


@needs_chromium
def test_every_column_of_a_noise_campaigns_table_is_in_sight_at_1400_px(tmp_path):
    rng = np.random.default_rng(1)
    points = [{"trial.duration_s": 120.0, "imu.errors.accel_noise_ug": [100 * (1 + p)] * 3} for p in range(2)]
    path = _kind_page(tmp_path, "noise", points, [_noise_row(rng, p, k) for p in range(2) for k in range(10)])
    assert measure(path, tmp_path)["clipped"] == []


@needs_chromium
def test_every_column_of_a_calibration_campaigns_table_is_in_sight_at_1400_px(tmp_path):
    rng = np.random.default_rng(2)
    points = [{"estimator.calibration.dwell_s": d, "imu.errors.accel_noise_ug": [50, 50, 50]} for d in (20, 60)]
    rows = [calibration_row(k, {t: (12.3 * rng.normal(), 12.3, 1234.5) for t in CALIBRATION_TERMS})
            | {"point": p, "id": f"p{p:03d}-r{k:04d}"} for p in range(2) for k in range(10)]
    assert measure(_kind_page(tmp_path, "calibration", points, rows), tmp_path)["clipped"] == []


def test_the_statistics_outside_their_band_are_the_bold_ones_of_the_highlighted_point(page):
    path, summary = page
    point = summary["points"][OPTIMISTIC]
    assert not point["nees_inside"] and not all(point["ratio_inside"])
    rows = re.findall(r"<tr( class=['\"]?row-FAIL['\"]?)?>(.*?)</tr>", path.read_text().split("<tbody>")[1])
    assert len(rows) == 3 * len(summary["points"])  # a row an axis
    highlighted = [k // 3 for k, (flag, _) in enumerate(rows) if flag]
    expected = [p for p, s in enumerate(summary["points"]) if not (s["nees_inside"] and all(s["ratio_inside"]))]
    assert sorted(set(highlighted)) == expected and OPTIMISTIC in expected
    bold = [re.findall(r"<strong>([^<]*)</strong>", cells) for _, cells in rows[3 * OPTIMISTIC: 3 * OPTIMISTIC + 3]]
    for k in range(3):
        outside = [f"{point['ratio'][k]:.3g}"] if not point["ratio_inside"][k] else []
        assert bold[k] == outside + ([f"{point['nees_mean']:.3g}"] if k == 0 else [])
