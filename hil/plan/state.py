"""``OUT/plan.json``: the plan's state, every step listed once, written atomically (a temporary file, then
``os.replace``) before and after every step, so that a plan killed at any moment (``kill -9`` included) resumes
from what it says: completed steps kept, the interrupted one run again."""

from __future__ import annotations

import json
import os
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from hil.inputs import InputError
from hil.plan.spec import TRIAL_KINDS, Plan, Step

STATE_NAME = "plan.json"


def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z")


def write_atomically(path: Path, text: str) -> None:
    """``text`` into ``path`` so that a reader (or a resumed plan) sees the old file or the new one, never a part."""
    temporary = path.with_name(f".{path.name}.tmp")
    with temporary.open("w", encoding="utf-8") as stream:
        stream.write(text)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(temporary, path)


class PlanState:
    """The document of ``OUT/plan.json`` for ``plan``, kept in step with the file."""

    def __init__(self, out: Path, doc: dict[str, Any]) -> None:
        self.out, self.doc = out, doc

    @classmethod
    def open(cls, out: Path, plan: Plan, resume: bool) -> PlanState:
        """A new plan's state in ``out``, or with ``resume`` the one its plan.json holds (the same plan's)."""
        path = out / STATE_NAME
        if path.exists() and not resume:
            raise InputError(f"--out {out}: holds a plan's outputs ({STATE_NAME}); --resume to go on with it, or "
                             "choose another directory")
        if resume and path.exists():
            doc = json.loads(path.read_text(encoding="utf-8"))
            if doc.get("plan_sha256") != plan.sha256:
                raise InputError(f"--resume: {path}: written by another plan (or this plan since changed); "
                                 "choose another directory")
            return cls(out, doc)
        doc = {"name": plan.name, "run": utc_now().replace("-", "").replace(":", ""), "plan": str(plan.path),
               "plan_sha256": plan.sha256, "config": str(plan.config_path), "started_utc": utc_now(),
               "ended_utc": None, "ended": None, "verdict": None,
               "steps": [_entry(step) for step in plan.steps], "units": {}}
        state = cls(out, doc)
        state.save()
        return state

    def save(self) -> None:
        write_atomically(self.out / STATE_NAME, json.dumps(self.doc, indent=2) + "\n")

    def entry(self, step: Step) -> dict[str, Any]:
        return self.doc["steps"][step.index - 1]

    def done(self, step: Step) -> bool:
        """Whether ``step`` completed in an earlier run of the plan (one interrupted, or ended early, runs again)."""
        return self.entry(step)["ended"] == "completed"

    def start(self, step: Step) -> None:
        self.entry(step).update(started_utc=utc_now(), ended_utc=None, ended=None, verdict=None)
        self.doc.update(ended_utc=None, ended=None, verdict=None)
        self.save()

    def finish(self, step: Step, ended: str, verdict: str | None, **more: Any) -> None:
        self.entry(step).update(ended_utc=utc_now(), ended=ended, verdict=verdict, **more)
        self.save()

    def close(self, ended: str, verdict: str | None, units: dict[str, Any]) -> None:
        self.doc.update(ended_utc=utc_now(), ended=ended, verdict=verdict, units=units)
        self.save()


def _entry(step: Step) -> dict[str, Any]:
    return {"index": step.index, "kind": step.kind, "repeat_of": step.block, "pass": step.repeat,
            "started_utc": None, "ended_utc": None, "ended": None, "verdict": None,
            "out_dir": step.out_name if step.kind in TRIAL_KINDS else None}
