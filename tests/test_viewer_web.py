"""The web viewer as a lab watches a trial: ``hil run --viewer serve`` of a short emulated swing, the page it
serves opened in headless Chromium with software WebGL, what the viewer holds read back through the page's own
API (its active blueprint and recording, its views and time cursor) and the page as drawn at 1600x1000.

Software rendering costs about a second of CPU a frame at that size, and the page draws a frame for each batch of
data it takes in: the page loads the trial in a small window, where a frame costs little, and is drawn full size
once it holds every row of the trial's recording.rrd. Each wait is for a condition, with a timeout far beyond
what it takes, never a fixed sleep: the module takes 30 to 40 s of CPU in all (Chromium's about 25), 35 to 100 s
on two busy cores.
"""

from __future__ import annotations

import io
import json
import queue
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import sync_playwright
from rerun.chunk import RrdReader

from hil.config import load_config
from hil.outputs.measurements import FAIL, PASS, measurements
from hil.viewer.blueprint import AXIS_COLORS, LIMIT_COLOR, TIMELINE, TRUTH_COLOR
from tests.pages import (CHROMIUM, SOFTWARE_GL, needs_chromium, open_viewer, settled_screenshot, viewer_encoded,
                         viewer_times, viewer_views, wait_for_recording)
from tests.test_viewer_record import _blueprint_views, _rows

pytestmark = [needs_chromium, pytest.mark.xdist_group("viewer_web")]  # one trial and one browser for the module

DURATION_S = 10
LOADING_WINDOW = (400, 250)  # px: the page takes in the data here, a frame costing a tenth of a full-size one
WINDOW = (1600, 1000)  # px: the page as drawn, docs/viewer.md's screenshots
TIMEOUT_S = 300.0  # each wait; it takes 5 to 30 s


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """(the URL ``hil run --viewer serve`` prints, its output directory) of a short emulated swing, served until
    the module's tests are done (then Ctrl-C, as a user stops it)."""
    out = tmp_path_factory.mktemp("served") / "out"
    process = subprocess.Popen([sys.executable, "-m", "hil.cli", "run", "--duration", str(DURATION_S), "--speed", "max",
                                "--viewer", "serve", "--no-figures", "--no-history", "--quiet", "--out", str(out)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
    lines: queue.Queue[str | None] = queue.Queue()
    threading.Thread(target=_read_lines, args=(process.stderr, lines), daemon=True).start()
    try:
        yield _serving_url(lines), out
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(30)
        except subprocess.TimeoutExpired:
            process.kill()


def _read_lines(stream, lines: queue.Queue[str | None]) -> None:
    for line in stream:
        lines.put(line)
    lines.put(None)  # the process closed its stderr: it ended


def _serving_url(lines: queue.Queue[str | None]) -> str:
    """The URL of ``viewer serving at URL; Ctrl-C to stop``, printed once the trial and its outputs are done."""
    seen: list[str] = []
    while True:
        try:
            line = lines.get(timeout=TIMEOUT_S)
        except queue.Empty:
            pytest.fail(f"hil run --viewer serve printed no URL in {TIMEOUT_S:g} s: {''.join(seen)}")
        if line is None:
            pytest.fail(f"hil run --viewer serve ended before serving: {''.join(seen)}")
        seen.append(line)
        if line.startswith("viewer serving at "):
            return line.removeprefix("viewer serving at ").split(";")[0]


@dataclass
class Seen:
    """What the web viewer showed of the served trial (``out``: its outputs): its active blueprint and recording as
    .rrd files, its state (``GetViewerStateResponse``) and the page drawn full size (RGB pixels)."""

    out: Path
    blueprint: Path
    recording: Path
    state: bytes
    pixels: np.ndarray


@pytest.fixture(scope="module")
def seen(served, tmp_path_factory) -> Seen:
    """The served trial's page: loaded in a small window, drawn full size once it holds the whole recording."""
    url, out = served
    folder = tmp_path_factory.mktemp("seen")
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=list(SOFTWARE_GL))
        try:
            page = open_viewer(browser, url, LOADING_WINDOW, TIMEOUT_S)
            recording = wait_for_recording(page, out / "recording.rrd", folder / "recording.rrd", TIMEOUT_S)
            shot = settled_screenshot(page, WINDOW, TIMEOUT_S)
            blueprint = folder / "blueprint.rrd"
            blueprint.write_bytes(viewer_encoded(page, "blueprint"))
            pixels = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB")).astype(int)
            return Seen(out, blueprint, recording, viewer_encoded(page, "state"), pixels)  # its views as drawn
        finally:
            browser.close()


def _contents(path: Path) -> dict[str, list[str]]:
    """The contents of each view of a .rrd's blueprint: view display name -> its entity path expressions."""
    reader = RrdReader(path)
    (blueprint,) = reader.blueprints()
    names, queries = {}, {}
    for chunk in reader.stream(store=blueprint):
        batch = chunk.to_record_batch()
        if "ViewBlueprint:display_name" in batch.schema.names:
            names[chunk.entity_path] = batch.column("ViewBlueprint:display_name").to_pylist()[-1][0]
        if "ViewContents:query" in batch.schema.names:
            view = chunk.entity_path.removesuffix("/ViewContents")
            queries[view] = batch.column("ViewContents:query").to_pylist()[-1]
    return {name: queries.get(view, []) for view, name in names.items()}


def _shown(expressions: list[str], origin: str, entities: set[str]) -> set[str]:
    """The entities a view's contents (``$origin/**``, ``/path/**`` or ``/path``) take from ``entities``."""
    shown = set()
    for expression in (e.replace("$origin", origin.rstrip("/")) for e in expressions):
        if expression.endswith("/**"):
            root = expression.removesuffix("/**") or "/"
            shown |= {e for e in entities if root == "/" or e == root or e.startswith(root + "/")}
        else:
            shown |= {expression} & entities
    return shown


def test_the_viewer_takes_in_every_row_the_trial_recorded(seen):
    # the wait ends on it; here what it means: the viewer's recording is the .rrd's, entity by entity
    recorded = {entity: len(rows) for entity, rows in _rows(seen.out / "recording.rrd").items()}
    assert {entity: len(rows) for entity, rows in _rows(seen.recording).items()} == recorded
    assert recorded["/bias/x/estimate"] >= 5 and recorded["/verdict"] >= 2


def test_the_viewer_lays_out_the_trials_blueprint_and_every_view_shows_data(seen):
    views, recorded = _blueprint_views(seen.blueprint), _blueprint_views(seen.out / "recording.rrd")
    assert {name: v["origin"] for name, v in views.items()} == {name: v["origin"] for name, v in recorded.items()}
    contents = _contents(seen.blueprint)
    assert contents == _contents(seen.out / "recording.rrd")
    entities = set(_rows(seen.recording))
    empty = [name for name, v in views.items() if not _shown(contents[name], v["origin"], entities)]
    assert sorted(empty) == [f"bias drift {a} (µg/h)" for a in "xyz"]  # the drift: observable after minutes
    drawn = viewer_views(seen.state)  # the views the viewer made of it, as it reports them
    assert sorted(v["name"] for v in drawn) == sorted(views)
    assert [(v["name"], v["reports"]) for v in drawn if v["reports"]] == []  # none failed to draw its data
    result = json.loads((seen.out / "result.json").read_text())
    for k, axis in enumerate("xyz"):
        (followed,) = [v for name, v in views.items() if name.startswith(f"bias {axis} (µg), converged")]
        low, high = followed["range"]  # the view follows the converged estimate
        assert low < result["estimate"]["accel_bias_ug"][k] < high


def test_the_verdict_panel_ends_with_result_jsons_verdict_and_every_judged_measurement(seen):
    result = json.loads((seen.out / "result.json").read_text())
    judged = [m for m in measurements(result, load_config(seen.out / "config.yaml").limits)
              if m.outcome in (PASS, FAIL)]
    last = _rows(seen.recording)["/verdict"][-1]
    assert last[0] == DURATION_S  # at the trial's last time
    text = last[1][0]
    assert text.startswith(f"## Verdict: {result['verdict']}\n") and result["verdict"] in (PASS, FAIL)
    assert {m.outcome for m in judged} == {PASS, FAIL}  # a 10 s trial: its alignment passes, its bias sigma fails
    for m in judged:
        (row,) = [line for line in text.splitlines() if line.startswith(f"| `{m.name}` |")]
        assert row.endswith(f"| {m.outcome} |" if m.outcome == PASS else f"| **{m.outcome}** |")
    # the viewer follows the trial to its end, so the panel shows that last text
    assert viewer_times(seen.state, TIMELINE) == [(DURATION_S * 10**9, DURATION_S * 10**9)]


def test_the_page_draws_the_bias_its_truth_and_the_sigma_limit(seen):
    height, width, _ = seen.pixels.shape
    assert (width, height) == WINDOW
    assert seen.pixels.std() > 10  # not a blank page
    bias_column = seen.pixels[:, : int(0.6 * width)]  # three fifths of the width
    for color in (*AXIS_COLORS.values(), TRUTH_COLOR, LIMIT_COLOR):
        drawn = int(np.all(bias_column == color, axis=2).sum())
        assert drawn > 300, f"{color}: {drawn} px, no more than a legend's dot"  # a line across a panel
    # the verdict panel, atop the side column: a table of dark text (about 3000 px), not a grey "(empty)"
    verdict = seen.pixels[int(0.08 * height) : int(0.3 * height), int(0.62 * width) : int(0.98 * width)].mean(axis=2)
    assert (verdict < 100).sum() > 1500
