"""The view of ``hil plan --viewer``: which step runs, the steps done with their verdicts and the time left, in
a recording of its own (OUT/plan.rrd, ``/plan`` a markdown document and ``/plan/step`` the step's index and the
count, on ``plan_time``: the plan's scheduled seconds at each step's start). Each swing and calibrate step logs
its own recording to the same viewer (its ``recording.rrd`` in its directory), its layout with the plan's
document beside its verdict (:func:`hil.viewer.blueprint.default_blueprint`)."""

from __future__ import annotations

from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from hil.viewer.own_recording import OwnRecording

PLAN_RRD = "plan.rrd"
TIMELINE = "plan_time"


def plan_markdown(name: str, entries: list[dict], running: int | None, left: str, ended: str | None = None,
                  verdict: str | None = None) -> str:
    """The plan's document: its head (the step running, or how the plan ended and its verdict; ``left`` the
    scheduled time left, as the console says it) and a row per step of plan.json's ``entries`` (done: how it
    ended and its verdict)."""
    if ended is not None:
        head = f"## Plan {name}: {ended}, verdict {verdict or 'none judged'}"
    elif running is not None:
        kind = entries[running - 1]["kind"]
        head = f"## Plan {name}: step {running} of {len(entries)}, {kind}, running; {left} left"
    else:
        head = f"## Plan {name}: {left} left"
    lines = [head, "", "| step | kind | outputs | ended | verdict |", "|---|---|---|---|---|"]
    for entry in entries:
        state = "**running**" if entry["index"] == running else entry["ended"] or "—"
        lines.append(f"| {entry['index']} | {entry['kind']} | {entry['out_dir'] or '—'} | {state} | "
                     f"{entry['verdict'] or '—'} |")
    return "\n".join(lines) + "\n"


def plan_blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Vertical(rrb.TextDocumentView(origin="/plan", name="plan: steps, verdicts, time left"),
                     rrb.TimeSeriesView(origin="/plan/step", name="step and steps"), row_shares=[3, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
    )


class PlanView(OwnRecording):
    """The plan's view in ``mode`` (``spawn``, ``serve`` or ``save``), OUT/plan.rrd in every mode; :attr:`text`
    the document last shown (what a step's own view shows of the plan)."""

    def __init__(self, mode: str, out: Path, name: str, bind: str = "127.0.0.1") -> None:
        super().__init__(mode, Path(out) / PLAN_RRD, plan_blueprint(), f"plan {name}", bind)
        self.text = ""
        self.rec.log("plan/step", rr.SeriesLines(names=["step", "steps"], colors=[(255, 170, 0), (150, 150, 150)]),
                     static=True)  # fmt: skip

    def show(self, t: float, text: str, index: int | None, steps: int) -> None:
        """The plan at its scheduled time t (s): ``text`` (:func:`plan_markdown`) and the step running (None:
        between steps)."""
        self.text = text
        self.rec.set_time(TIMELINE, duration=t)
        self.rec.log("plan", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN))
        if index is not None:
            self.rec.log("plan/step", rr.Scalars([index, steps]))
