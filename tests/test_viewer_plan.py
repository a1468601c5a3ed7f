"""The view of ``hil plan --viewer``: the step running, the steps done with their verdicts and the time left in the
plan's recording, and each swing step's own recording with the plan's document beside its verdict, exactly the
entities docs/viewer.md names."""

from __future__ import annotations

import json

import pytest
import yaml
from test_viewer_record import _blueprint_views, _recorded, documented
from rerun.chunk import RrdReader

from hil.cli import main


@pytest.fixture(scope="module")
def plan_out(tmp_path_factory):
    """A plan of a 20 s swing, a 30 s wait and a 10 s swing, with ``--viewer save``."""
    tmp = tmp_path_factory.mktemp("plan")
    plan = tmp / "plan.yaml"
    plan.write_text(yaml.safe_dump({"name": "viewed", "config": "configs/emulated_swing.yaml", "steps": [
        {"swing": {"trial": {"duration_s": 20}}}, {"wait": {"s": 30}}, {"swing": {"trial": {"duration_s": 10}}}]}))
    out = tmp / "out"
    main(["plan", str(plan), "--out", str(out), "--speed", "max", "--no-figures", "--no-history", "--viewer", "save"])
    return out


def _texts(path) -> list[tuple[float, str]]:
    """The ``/plan`` documents of a .rrd's recording: (time s, markdown), in time order (static: time None)."""
    reader = RrdReader(path)
    (recording,) = reader.recordings()
    texts = []
    for chunk in reader.stream(store=recording):
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/plan":
            times = [None] * batch.num_rows if chunk.is_static else \
                batch.column("plan_time").cast("int64").to_numpy() / 1e9
            texts += [(t, text[0]) for t, text in zip(times, batch.column("TextDocument:text").to_pylist())]
    return sorted(texts, key=lambda row: row[0] or 0.0)


def test_the_plans_view_holds_exactly_the_entities_docs_viewer_names(plan_out):
    trial, plan_paths = documented()[0], documented()[4]
    assert _recorded(plan_out / "plan.rrd") == plan_paths
    assert _recorded(plan_out / "01-swing" / "recording.rrd") - trial == {"/plan"}


def test_the_plans_view_shows_the_step_running_and_the_steps_done_with_their_verdicts(plan_out):
    doc = json.loads((plan_out / "plan.json").read_text())
    texts = _texts(plan_out / "plan.rrd")
    assert [t for t, _ in texts] == [0.0, 20.0, 20.0, 50.0, 50.0, 60.0, 60.0]  # each step's start and end, the end
    assert texts[0][1].startswith("## Plan viewed: step 1 of 3, swing, running; 60 s left")
    assert "| 1 | swing | 01-swing | **running** | — |" in texts[0][1]
    verdict = doc["steps"][0]["verdict"]
    assert f"| 1 | swing | 01-swing | completed | {verdict} |" in texts[3][1]
    assert texts[4][1].startswith("## Plan viewed: step 3 of 3, swing, running; 10 s left")
    last = texts[-1][1]
    assert last.startswith(f"## Plan viewed: completed, verdict {doc['verdict']}\n")
    for entry in doc["steps"]:
        assert f"| {entry['index']} | {entry['kind']} | {entry['out_dir'] or '—'} | completed | " \
               f"{entry['verdict'] or '—'} |" in last


def test_a_steps_own_view_has_the_plan_beside_its_verdict(plan_out):
    ((_, text),) = _texts(plan_out / "03-swing" / "recording.rrd")
    assert text.startswith("## Plan viewed: step 3 of 3, swing, running")
    views = _blueprint_views(plan_out / "03-swing" / "recording.rrd")
    assert {v["origin"] for v in views.values()} >= {"/plan", "/verdict", "/bias/x"}
