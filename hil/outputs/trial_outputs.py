"""Every output of a trial in its directory: result.json, series.csv, config.yaml, the figures,
report.html and junit.xml."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from hil.config import ReportLimits
from hil.estimation.online import Snapshot
from hil.outputs.figures import Draw, write_figures
from hil.outputs.judgement import Judgement, as_written, judge
from hil.outputs.result import write_result
from hil.outputs.series import write_series
from hil.outputs.trial_report import write_judged_report


def write_trial_outputs(out: Path, result: dict, snapshots: list[Snapshot], limits: ReportLimits,
                        config_text: str | None = None, figures: bool = True,
                        draw: Draw = write_figures, temperatures: Mapping[float, float] | None = None) -> Judgement:
    """Write the outputs of a finished trial (figures drawn once, from the snapshots, by ``draw``: e.g. a
    :class:`~hil.outputs.figure_process.FigureProcess`'s); returns its judgement, its measurements computed once
    from result.json as written, for the report, junit.xml and whoever reads them next, and its verdict, also
    result.json's ``verdict``: PASS or FAIL against ``limits`` for a completed trial, else how it ended
    (:func:`~hil.outputs.result.trial_verdict`). Without ``figures`` the report still embeds them, drawn into a
    temporary directory. ``temperatures``: the IMU's at each snapshot's time, for series.csv."""
    out.mkdir(parents=True, exist_ok=True)
    if config_text is not None:
        (out / "config.yaml").write_text(config_text)
    document = as_written(result)
    judged = judge(document, limits)
    result["verdict"] = document["verdict"] = judged.verdict
    write_result(out, result)
    series = write_series(out, snapshots, temperatures)
    if figures and len(series):
        draw(out, series, result)
    write_judged_report(out, document, judged, draw)
    return judged
