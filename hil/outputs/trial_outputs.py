"""Every output of a trial in its directory: result.json, series.csv, config.yaml, the figures,
report.html and junit.xml."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from hil.config import ReportLimits
from hil.estimation.online import Snapshot
from hil.outputs.figures import Draw, write_figures
from hil.outputs.measurements import measurements, overall
from hil.outputs.trial_report import write_report
from hil.outputs.result import trial_verdict, write_result
from hil.outputs.series import write_series


def write_trial_outputs(out: Path, result: dict, snapshots: list[Snapshot], limits: ReportLimits,
                        config_text: str | None = None, figures: bool = True,
                        draw: Draw = write_figures, temperatures: Mapping[float, float] | None = None) -> str:
    """Write the outputs of a finished trial (figures drawn once, from the snapshots, by ``draw``: e.g. a
    :class:`~hil.outputs.figure_process.FigureProcess`'s); returns the verdict, also result.json's ``verdict``: PASS
    or FAIL against ``limits`` for a completed trial, else how it ended (:func:`~hil.outputs.result.trial_verdict`).
    Without ``figures`` the report still embeds them, drawn into a temporary directory. ``temperatures``: the IMU's
    at each snapshot's time, for series.csv."""
    out.mkdir(parents=True, exist_ok=True)
    if config_text is not None:
        (out / "config.yaml").write_text(config_text)
    result["verdict"] = trial_verdict(result["ended"], overall(measurements(result, limits)))
    write_result(out, result)
    series = write_series(out, snapshots, temperatures)
    if figures and len(series):
        draw(out, series, result)
    write_report(out, limits, draw)
    return result["verdict"]
