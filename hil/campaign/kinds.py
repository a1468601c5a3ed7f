"""What a campaign's ``kind`` runs and reports: per kind, the run a worker executes (a task to its row), the
summary of a sweep point's rows, the console lines of that summary and the section of campaign.html.
Wiring a kind is one entry here (and its name in
:class:`hil.campaign.spec.CampaignSpec`'s ``kind``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hil.campaign import calibration_summary, noise_summary, swing_summary
from hil.campaign.calibration_consistency import calibration_section
from hil.campaign.noise_consistency import noise_section
from hil.campaign.campaign_report import swing_section
from hil.campaign.runs import run_calibration, run_noise, run_swing
from hil.campaign.task import RunTask

Row = dict[str, Any]


@dataclass(frozen=True)
class Kind:
    run: Callable[[RunTask], Row]  # one run, as a worker executes it; a run that raises is a row with its error
    point_summary: Callable[[int, dict[str, Any], list[Row]], dict[str, Any]]  # a sweep point in summary.json
    lines: Callable[[dict[str, Any]], list[str]]  # a sweep point's console lines
    section: Callable[[dict, list[Row], Any], str]  # campaign.html's part for the kind (summary, rows, pyplot)


KINDS = {
    "swing": Kind(run_swing, swing_summary.point_summary, swing_summary.point_lines, swing_section),
    "noise": Kind(run_noise, noise_summary.point_summary, noise_summary.point_lines, noise_section),
    "calibration": Kind(run_calibration, calibration_summary.point_summary, calibration_summary.point_lines,
                        calibration_section),
}
