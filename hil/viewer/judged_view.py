"""What a trial's view shows of its judgement: the limits drawn where they apply (the 1σ limit under the 1σ
curves, the convergence deadline as a vertical line once reached), ``/verdict`` as it forms
(:mod:`hil.viewer.verdict`), and the followed bias ranges (:mod:`hil.viewer.bias_view`) sent to a live view
in its blueprint as sigma shrinks, and to the .rrd's blueprint at the end."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hil.config import ReportLimits
from hil.estimation.online import Snapshot
from hil.units import UG
from hil.viewer.bias_view import follow_ranges, moved
from hil.viewer.blueprint import TIMELINE, default_blueprint
from hil.viewer.verdict import VerdictSoFar

SIGMA_SPAN = 3.0  # the 1σ panel spans 0 to this many times the latest 1σ (and the limit)
VERDICT_PERIOD_S = 10.0  # the verdict so far and the followed bias ranges are sent again this often (trial time)

ScalarRows = Callable[[str, np.ndarray, np.ndarray], None]  # rows (N, K) of an entity at trial times (N,)


class JudgedView:
    """The judgement of one trial's view; ``limits`` None: nothing judged, only the followed ranges."""

    def __init__(self, limits: ReportLimits | None, truth_bias: np.ndarray | None, extra: rrb.Container | None,
                 plan: bool = False) -> None:
        self.limits = limits
        self.truth_bias = truth_bias
        self.extra = extra  # the trial kind's own column of the blueprint (a calibration's)
        self.plan = plan  # the trial is a plan's step: the plan's document beside the verdict
        truth_ug = None if truth_bias is None else truth_bias / UG
        self.verdict = None if limits is None else VerdictSoFar(limits, truth_ug, calibration=extra is not None)
        self._next_t = 0.0
        self._follow: dict[str, tuple[float, float]] | None = None  # the followed ranges the live view was sent
        self._latest: Snapshot | None = None
        self._sigma_max = 0.0  # µg, the largest 1σ so far: the height of the convergence deadline's marker
        self._deadline_drawn = False
        self._verdict_t: float | None = None  # the trial time of the last verdict so far logged

    def snapshots(self, snaps: list[Snapshot], sigma_ug: np.ndarray, scalars: ScalarRows, rec, view) -> None:
        """New snapshots (their 1σ in µg): the limits' rows through ``scalars``; every ``VERDICT_PERIOD_S`` the
        verdict so far to ``rec`` (all streams) and, when moved, the followed ranges to the live ``view``."""
        t = np.fromiter((s.t for s in snaps), float, len(snaps))
        self._limits(t, sigma_ug, scalars)
        self._latest = snaps[-1]
        if self.verdict is not None:
            self.verdict.add(snaps)
        if self._latest.t < self._next_t:
            return
        self._next_t = self._latest.t + VERDICT_PERIOD_S
        self._log_verdict(rec)
        follow = self._ranges()
        if view is not None and follow is not None and moved(self._follow, follow):
            self._follow = follow
            view.send_blueprint(self.blueprint(follow))

    def finish(self, rec, file: rr.RecordingStream, view: rr.RecordingStream | None) -> None:
        """At the end of the data: the verdict so far, the .rrd's blueprint (the ranges of the converged estimate)
        and the live view's."""
        if self._latest is None:
            file.send_blueprint(self.blueprint(None))
            return
        self._log_verdict(rec)
        follow = self._ranges()
        file.send_blueprint(self.blueprint(follow))
        if view is not None and follow is not None:
            view.send_blueprint(self.blueprint(follow))

    def _log_verdict(self, rec) -> None:
        """The verdict so far at the latest snapshot's time, unless logged there already."""
        if self.verdict is not None and self._latest.t != self._verdict_t:
            self._verdict_t = self._latest.t
            log_verdict(rec, self._latest.t, self.verdict.markdown())

    def blueprint(self, follow: dict[str, tuple[float, float]] | None) -> rrb.Blueprint:
        return default_blueprint(self.extra, follow, self.plan)

    def _ranges(self) -> dict[str, tuple[float, float]] | None:
        """The followed bias ranges (µg) per axis and the 1σ panel's, ``sigma``: from 0 to ``SIGMA_SPAN`` times the
        largest latest 1σ, the limit in view; None while the bias is not estimated."""
        follow = follow_ranges(self._latest, self.truth_bias)
        if follow is None:
            return None
        top = SIGMA_SPAN * float(np.max(self._latest.full.bias_sigma)) / UG
        limit = None if self.limits is None else self.limits.bias_sigma_ug_max
        return follow | {"sigma": (0.0, top if limit is None else max(top, 1.5 * limit))}

    def _limits(self, t: np.ndarray, sigma_ug: np.ndarray, scalars: ScalarRows) -> None:
        limits = self.limits
        if limits is None:
            return
        if limits.bias_sigma_ug_max is not None:
            scalars("sigma/limit", t, np.full(len(t), limits.bias_sigma_ug_max))
        if np.isfinite(sigma_ug).any():
            self._sigma_max = max(self._sigma_max, float(np.nanmax(sigma_ug)))
        deadline = limits.converged_by_s
        if deadline is not None and not self._deadline_drawn and t[-1] >= deadline and self._sigma_max > 0:
            self._deadline_drawn = True
            scalars("sigma/converged_by", np.full(2, deadline), np.array([0.0, self._sigma_max]))


def log_verdict(rec, t: float, markdown: str, entity: str = "verdict") -> None:
    """``/verdict`` (or ``entity``) at trial time t."""
    rec.set_time(TIMELINE, duration=t)
    rec.log(entity, rr.TextDocument(markdown, media_type=rr.MediaType.MARKDOWN))


def log_plan(rec, plan: str | None) -> None:
    """``/plan``: the document of the plan the trial is a step of (:mod:`hil.viewer.plan_view`; None: none)."""
    if plan is not None:
        rec.log("plan", rr.TextDocument(plan, media_type=rr.MediaType.MARKDOWN), static=True)
