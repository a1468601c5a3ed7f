"""history.html's figures over time, read from matplotlib's objects: a legend naming every line, and a time
axis that spans the trials (hours for a day's trials, not years)."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import matplotlib.dates as mdates
import numpy as np
import pytest

from hil.history.page import series_figure, trial_series


def swing(started: datetime, bias: list[float], dut: str | None = "A", replay_of: str | None = None,
          converged_at_s: float | None = 120.0) -> dict:
    return {"kind": "swing", "ended": "completed", "dut_serial": dut, "replay_of": replay_of,
            "started_utc": started.isoformat(timespec="seconds"),
            "figures": {"accel_bias_ug": bias, "drift_ug_per_h": [0.1, 0.2, 0.3], "converged_at_s": converged_at_s}}


def swing_figure(trials: list[dict]):
    ((title, series),) = [(t, s) for t, s in trial_series(trials) if s]
    return series_figure(title, series)


def span_days(fig) -> float:
    return float(np.diff(fig.axes[0].get_xlim())[0])


START = datetime(2026, 12, 4, 9, 30, tzinfo=timezone.utc)


@pytest.mark.parametrize("offsets_h", [[0.0], [0.0, 2.5, 7.0]])
def test_trials_within_a_day_get_a_time_axis_of_hours_around_them(offsets_h):
    fig = swing_figure([swing(START + timedelta(hours=h), [1.0, 2.0, 3.0]) for h in offsets_h])
    lo, hi = (mdates.num2date(x) for x in fig.axes[0].get_xlim())
    assert lo < START and hi > START + timedelta(hours=offsets_h[-1])
    assert span_days(fig) == pytest.approx((offsets_h[-1] + 1.0) / 24, rel=1e-6)  # half an hour either side


def test_every_plot_over_time_has_a_legend_naming_its_axes_and_its_units():
    fig = swing_figure([swing(START, [1.0, 2.0, 3.0])])
    assert [ax.get_ylabel() for ax in fig.axes] == ["accel_bias_ug", "drift_ug_per_h"]
    assert all([t.get_text() for t in ax.get_legend().get_texts()] == ["x", "y", "z"] for ax in fig.axes)
    fig = swing_figure([swing(START, [1.0, 2.0, 3.0]), swing(START + timedelta(days=40), [4.0, 5.0, 6.0], dut="B")])
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["A x", "A y", "A z", "B x", "B y", "B z"]
    assert 40 < span_days(fig) < 45  # the 40 days and a margin


def test_only_the_runs_of_the_repeatability_are_plotted_never_a_replay_or_an_unconverged_trial():
    replay = swing(START + timedelta(days=1), [1.5, 2.5, 3.5], replay_of="/runs/a1")
    short = swing(START + timedelta(days=2), [900.0, -400.0, 80.0], converged_at_s=None)
    unnamed = swing(START + timedelta(days=3), [1.2, 2.2, 3.2], dut=None)
    fig = swing_figure([swing(START, [1.0, 2.0, 3.0]), replay, short, unnamed])
    lines = fig.axes[0].get_lines()
    assert [(line.get_label(), list(line.get_ydata())) for line in lines[::3]] == [("A x", [1.0]),
                                                                                  ("(no serial) x", [1.2])]
