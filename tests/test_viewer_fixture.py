"""The fixture's overview of a units trial (hil/viewer/fixture_view.py) on its own: a unit's thread never waits for
it, ``none`` makes none, and the fixture's table names every unit, an absent one too. A units trial's overview is
read back in tests/test_units_live.py."""

from __future__ import annotations

import threading

import pytest
from tests.helpers import PAPER_ERRORS, make_config
from tests.test_viewer_record import _rows

from emulators.simulation import Simulation
from hil.estimation.online import OnlineEstimator
from hil.trial.viewer_feed import fixture_view
from hil.viewer import log_jobs
from hil.viewer.fixture_view import FixtureView, fixture_markdown
from hil.viewer.modes import ViewerOptions


@pytest.fixture(scope="module")
def snapshots():
    """The 1 Hz snapshots of a 20 s emulated swing at 100 Hz."""
    cfg = make_config(duration=20.0, rate=100.0, errors=PAPER_ERRORS)
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0)
    for batch in sim.batches(chunk=1000):
        est.update_many(batch)
    return est.snapshots


def test_a_units_snapshots_never_wait_for_a_stalled_overview(snapshots, tmp_path, monkeypatch):
    monkeypatch.setattr(log_jobs, "QUEUE_ITEMS", 4)
    view = FixtureView(ViewerOptions("save"), tmp_path, "bench")
    view.listener("a", "A-1", None)
    view.open(["a"], None)
    release = threading.Event()
    view._jobs.queue.put(release.wait)  # the logging thread is stuck in this job
    for _ in range(60):  # a call that waited would wait for ever: the thread is held until after
        view.log_snapshots("a", [snapshots[-1]])
    release.set()
    view.unit_verdict("a", "## Verdict: PASS\n")
    view.end({"ended": "completed", "verdict": "PASS",
              "units": [{"name": "a", "dut_serial": "A-1", "ended": "completed", "verdict": "PASS"}]})
    assert 60 - 4 <= view.dropped <= 60 - 3 and view.error is None
    rows = _rows(tmp_path / "fixture.rrd")
    assert 3 <= len(rows["/units/a/bias/x/estimate"]) <= 4  # those queued before it fell behind
    assert rows["/units/a/verdict"][-1][1][0] == "## Verdict: PASS\n"


def test_viewer_none_makes_no_overview(snapshots, tmp_path):
    cfg = make_config(duration=20.0)
    assert fixture_view(ViewerOptions("none"), cfg, tmp_path / "out") is None
    view = FixtureView(ViewerOptions("none"), tmp_path / "none", "bench")
    listener = view.listener("a", None, None)
    view.open(["a"], None)
    view.log_snapshots("a", snapshots)
    view.unit_verdict("a", "## Verdict: PASS\n")
    view.end({"ended": "completed", "verdict": "PASS", "units": []})
    assert callable(listener) and view.rrd_path is None and not (tmp_path / "none").exists()


def test_the_fixtures_table_has_a_row_per_unit_an_absent_one_too():
    rows = [{"name": "kvh-a", "dut_serial": "KVH-1", "ended": "completed", "verdict": "PASS"},
            {"name": "xsens", "dut_serial": None, "ended": "absent: /dev/ttyUSB9: no such device | gone",
             "verdict": "ABSENT"}]  # fmt: skip
    text = fixture_markdown("fixture-7", rows, "completed", "PASS")
    assert text.splitlines() == [
        "## Fixture fixture-7: PASS (completed)", "",
        "| unit | serial | ended | verdict |", "|---|---|---|---|",
        "| kvh-a | KVH-1 | completed | PASS |",
        "| xsens | — | absent: /dev/ttyUSB9: no such device \\| gone | ABSENT |"]  # fmt: skip
    running = fixture_markdown("fixture-7", [{"name": "kvh-a", "dut_serial": "KVH-1"}])
    assert running.splitlines()[0] == "## Fixture fixture-7: running" and "| kvh-a | KVH-1 | running | — |" in running
