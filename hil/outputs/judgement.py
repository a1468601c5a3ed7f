"""A trial's judgement: its measurements (:func:`hil.outputs.measurements.measurements`) computed once, from its
result.json document as written, and the verdict they make; report.html, junit.xml, the viewer's ``/verdict``,
the history's row and hil noise's check of its acquisition all read this one list."""

from __future__ import annotations

import json
from dataclasses import dataclass

from hil.config import ReportLimits
from hil.outputs.measurements import Measurement, measurements, overall
from hil.outputs.result import strict_json, trial_verdict


@dataclass(frozen=True)
class Judgement:
    """The measurements of one trial, judged against its limits, and its verdict (PASS or FAIL for a completed
    trial, else how it ended: :func:`~hil.outputs.result.trial_verdict`)."""

    measurements: tuple[Measurement, ...]
    verdict: str


def judge(document: dict, limits: ReportLimits) -> Judgement:
    """The judgement of a result.json ``document`` (as read back from the file) against ``limits``."""
    results = tuple(measurements(document, limits))
    return Judgement(results, trial_verdict(document["ended"], overall(list(results))))


def as_written(result: dict) -> dict:
    """``result`` as result.json holds it (:func:`~hil.outputs.result.write_result`) and a reader gets it back:
    plain JSON types, null for a non-finite number."""
    return json.loads(json.dumps(strict_json(result), allow_nan=False))
