"""campaign.html as a lab sees it in a 1400 px window: every column of the consistency table in sight, and the
statistic that puts a sweep point outside its band marked."""

from __future__ import annotations

import re

import numpy as np
import pytest
from pages import WINDOW_PX, clipped_columns, layout_width, needs_chromium

from hil.campaign.campaign_report import write_campaign_report
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


@needs_chromium
def test_every_column_of_the_campaign_table_is_in_sight_at_1400_px(page, tmp_path):
    path, _ = page
    assert clipped_columns(path, tmp_path) == []
    assert layout_width(path, tmp_path) <= WINDOW_PX


def test_the_statistics_outside_their_band_are_the_bold_ones_of_the_highlighted_point(page):
    path, summary = page
    point = summary["points"][OPTIMISTIC]
    assert not point["nees_inside"] and not all(point["ratio_inside"])
    rows = re.findall(r"<tr( class='row-FAIL')?>(.*?)</tr>", path.read_text().split("<tbody>")[1])
    assert len(rows) == 3 * len(summary["points"])  # a row an axis
    highlighted = [k // 3 for k, (flag, _) in enumerate(rows) if flag]
    expected = [p for p, s in enumerate(summary["points"]) if not (s["nees_inside"] and all(s["ratio_inside"]))]
    assert sorted(set(highlighted)) == expected and OPTIMISTIC in expected
    bold = [re.findall(r"<strong>([^<]*)</strong>", cells) for _, cells in rows[3 * OPTIMISTIC: 3 * OPTIMISTIC + 3]]
    for k in range(3):
        outside = [f"{point['ratio'][k]:.3g}"] if not point["ratio_inside"][k] else []
        assert bold[k] == outside + ([f"{point['nees_mean']:.3g}"] if k == 0 else [])
