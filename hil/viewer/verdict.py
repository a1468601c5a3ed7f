"""The ``/verdict`` text of a trial's view: every judged measurement (a limit in ``output.limits``) with its value,
its limit and its outcome, as report.html and junit.xml list them (:func:`hil.outputs.measurements.measurements`,
the values shown by :func:`~hil.outputs.measurements.format_value`).

While the trial runs the measurements are those of a result.json document of the trial so far
(:class:`VerdictSoFar`): a measurement without a value yet, or a convergence time not reached before its
deadline, is ``pending`` (a calibration's figures, fitted at the end, stay so); at the end the text is the
trial's judgement (:class:`~hil.outputs.judgement.Judgement`), the one its report.html and junit.xml show.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hil.config import ReportLimits
from hil.estimation.convergence import BIAS_TOLERANCE, SolveTrack, convergence_time
from hil.estimation.online import Snapshot
from hil.outputs.judgement import Judgement
from hil.outputs.measurements import FAIL, NOT_JUDGED, Measurement, format_value, measurements
from hil.units import DEG, UG

PENDING = "pending"
TAIL = 0.1  # result.json's alignment errors: the mean over the last 10 % of the trial


def verdict_markdown(heading: str, results: Sequence[Measurement]) -> str:
    """The markdown of the judged measurements under ``heading``: a table of name, value, limit, outcome."""
    lines = [f"## {heading}", "", "| measurement | value | limit | outcome |", "|---|---|---|---|"]
    for m in results:
        if m.limit:
            value = f"{m.shown} {m.unit}".rstrip() if m.value is not None else "—"
            outcome = f"**{m.outcome}**" if m.outcome == FAIL else m.outcome
            limit = f"{m.limit} {m.unit}".rstrip().replace("|", "\\|")  # |x| inside a table cell
            lines.append(f"| `{m.name}` | {value} | {limit} | {outcome} |")
    if len(lines) == 4:
        lines.append("| (no limits in output.limits) | | | |")
    return "\n".join(lines) + "\n"


def final_markdown(judged: Judgement) -> str:
    """The text at the end: the trial's verdict and its judged measurements, as report.html lists them."""
    return verdict_markdown(f"Verdict: {judged.verdict}", judged.measurements)


class VerdictSoFar:
    """The measurements of the trial so far, from the snapshots and stream counters a viewer is given.

    ``truth`` is result.json's (``accel_bias_ug``, µg), None for a real device; ``calibration``: a calibration
    trial, whose fit's figures are pending until the end."""

    def __init__(self, limits: ReportLimits, truth_ug: np.ndarray | None = None, calibration: bool = False) -> None:
        self.limits = limits
        self.calibration = calibration
        self.truth_ug = None if truth_ug is None else [float(b) for b in truth_ug]
        self._bias = SolveTrack(7)  # t, bias, its sigma (m/s^2)
        self._method2 = SolveTrack(3)  # t, pitch, roll (rad)
        self._latest: Snapshot | None = None
        self.streams: dict = {}  # result.json's streams so far

    def take_streams(self, streams: dict) -> None:
        """result.json's stream counters so far."""
        self.streams = streams

    def add(self, snaps: list[Snapshot]) -> None:
        """Snapshots in time order."""
        for s in snaps:
            bias = s.full.bias if s.full.bias is not None else np.full(3, np.nan)
            sigma = s.full.bias_sigma if s.full.bias_sigma is not None else np.full(3, np.nan)
            self._bias.append(np.concatenate(([s.t], bias, sigma)))
            if s.error_method2 is not None:
                self._method2.append(np.array([s.t, s.error_method2[0], s.error_method2[1]]))
            self._latest = s

    def result(self) -> dict:
        """A result.json document of the trial so far (the figures the measurements read)."""
        t = 0.0 if self._latest is None else self._latest.t
        result = {"trial": {"duration_s": t}, "streams": dict(self.streams), "estimate": self._estimate(),
                  "alignment_deg": {"method2": self._method2_tail(t)}}
        if self.truth_ug is not None:
            result["truth"] = {"accel_bias_ug": self.truth_ug}
        if self.calibration:
            result["calibration"] = {"residual_max_ug": None, "worst_error_sigma": None}
        return result

    def _estimate(self) -> dict:
        """result.json's ``estimate`` so far: the latest bias and its sigma, the convergence time over every
        snapshot."""
        rows = self._bias.rows
        converged = convergence_time(rows[:, 0], rows[:, 1:4], rows[:, 4:7], BIAS_TOLERANCE) if len(rows) else None
        if self._latest is None:
            return {"accel_bias_ug": None, "accel_bias_sigma_ug": None, "observable": False, "converged_at_s": None}
        full = self._latest.full
        estimate = {"bias_model": "constant", "accel_bias_ug": _ug(full.bias), "accel_bias_sigma_ug": _ug(full.bias_sigma),
                    "observable": full.observable, "converged_at_s": converged}  # fmt: skip
        if full.drift is not None:  # the drift model: the bias at the start is judged against the truth
            estimate |= {"bias_model": "drift", "accel_bias_t0_ug": _ug(full.bias_t0),
                         "accel_bias_t0_sigma_ug": _ug(full.bias_t0_sigma)}  # fmt: skip
        return estimate

    def _method2_tail(self, t: float) -> dict[str, float] | None:
        """The method-2 pitch and roll errors (deg) averaged over the last ``TAIL`` of the trial so far."""
        rows = self._method2.rows
        tail = rows[rows[:, 0] >= (1.0 - TAIL) * t]
        if not len(tail):
            return None
        return {"pitch": float(np.mean(tail[:, 1])) / DEG, "roll": float(np.mean(tail[:, 2])) / DEG}

    def measurements(self) -> list[Measurement]:
        """The measurements so far, a judged one without a value yet (or not converged before its deadline)
        ``pending``."""
        return [_so_far(m) for m in measurements(self.result(), self.limits)]

    def markdown(self) -> str:
        """The text while the trial runs: the measurements so far and the verdict they would make now."""
        results = self.measurements()
        judged = [m.outcome for m in results if m.limit and m.outcome != NOT_JUDGED]
        now = FAIL if FAIL in judged else PENDING if PENDING in judged else "PASS"
        t = 0.0 if self._latest is None else self._latest.t
        return verdict_markdown(f"Verdict so far: {now} (trial running, {format_value(round(t))} s)", results)


def _so_far(m: Measurement) -> Measurement:
    """``m`` while the trial runs: pending when judged but without a value yet, unless it is a convergence time
    past its deadline (FAIL) or a limit that does not apply (NOT_JUDGED, the bias error without truth)."""
    waiting = m.outcome == NOT_JUDGED if m.name == "converged_at" else m.outcome == FAIL
    if m.limit and m.value is None and waiting:
        return Measurement(m.name, m.value, m.unit, m.limit, PENDING, m.description, m.sigma)
    return m


def _ug(v: np.ndarray | None) -> list[float] | None:
    return None if v is None else [float(x) for x in np.asarray(v) / UG]
