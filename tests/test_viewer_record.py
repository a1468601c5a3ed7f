"""The recording a trial writes is the one docs/viewer.md describes: the same entity paths, the size it
states for a 60 s trial, the bias series of every axis against its references, the verdict as it forms and
at the end result.json's, and the layout with the bias first."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from hil.cli import main
from hil.config import load_config
from hil.estimation.calibration_schedule import default_schedule
from hil.frames import TableGeometry
from hil.outputs.judgement import judge
from hil.outputs.measurements import FAIL, PASS, measurements
from hil.trial.viewer_feed import watched_chamber
from hil.viewer import trial_viewer
from hil.viewer.modes import ViewerOptions
from hil.viewer.trial_viewer import TrialViewer
from hil.viewer.verdict import final_markdown

DOCS = Path(__file__).resolve().parents[1] / "docs" / "viewer.md"


def _recorded(path: Path) -> set[str]:
    """The entity paths of the recording (not the blueprint) in a .rrd."""
    reader = RrdReader(path)
    (recording,) = reader.recordings()
    return {chunk.entity_path for chunk in reader.stream(store=recording)} - {"/__properties"}


PARTS = ("`hil calibrate` adds", "**With a chamber**", "**`hil noise`**", "**`hil plan`**",
         "**Units: the fixture's overview**")  # after the trial's


def documented() -> list[set[str]]:
    """The entity paths docs/viewer.md's "Entity paths" names: the trial's table, then ``hil calibrate``'s, a
    chamber's, ``hil noise``'s, ``hil plan``'s and a units trial's overview (``PARTS``; its paths name each unit
    ``<name>``)."""
    text = DOCS.read_text().split("## Entity paths", 1)[1].split("\n## ", 1)[0]
    sections = []
    for marker in PARTS:
        head, text = text.split(marker, 1)
        sections.append(head)
    sections.append(text)

    def paths(text: str) -> set[str]:
        cells = [line.split("|")[1] for line in text.splitlines() if line.startswith("| `/")]
        return {p for cell in cells for p in re.findall(r"`(/[^`…]*)`", cell)}

    return [paths(part) for part in sections]


def _stated_mb_per_60_s() -> float:
    """The size docs/viewer.md states for the .rrd of a 60 s emulated trial."""
    found = re.search(r"a 60 s trial \(`[^`]+`\) writes ([0-9.]+) MB", DOCS.read_text())
    assert found, "docs/viewer.md states no size of a 60 s trial's .rrd"
    return float(found.group(1))


@pytest.fixture(scope="module")
def trial_rrd(tmp_path_factory) -> Path:
    """The .rrd of a 60 s emulated swing run as fast as it goes."""
    out = tmp_path_factory.mktemp("trial") / "out"
    main(["run", "--duration", "60", "--speed", "max", "--viewer", "save", "--no-figures", "--no-history",
          "--quiet", "--out", str(out)])  # fmt: skip
    return out / "recording.rrd"


def test_a_trials_recording_holds_exactly_the_entities_docs_viewer_names(trial_rrd):
    assert _recorded(trial_rrd) == documented()[0]


def test_a_60_s_trials_recording_is_the_size_docs_viewer_states(trial_rrd):
    stated = _stated_mb_per_60_s()
    measured = trial_rrd.stat().st_size / 1e6
    assert stated <= 0.6  # the MCAP of the raw bytes of such a trial is 0.75 MB
    assert measured == pytest.approx(stated, rel=0.15)


def test_a_trials_recording_holds_a_few_chunks_per_entity_whatever_its_pace(trial_rrd):
    reader = RrdReader(trial_rrd)
    (recording,) = reader.recordings()
    chunks: dict[str, int] = {}
    rows: dict[str, int] = {}
    for chunk in reader.stream(store=recording):
        if not chunk.is_static:
            chunks[chunk.entity_path] = chunks.get(chunk.entity_path, 0) + 1
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert rows["/table/angles_deg"] == 601  # 10 Hz, 0 to 60 s
    assert chunks.pop("/verdict") == 2  # the trial's texts, then result.json's once written
    assert set(chunks.values()) == {1}  # every entity's rows in one chunk: the first flush is at 2 minutes
    assert 5 <= rows["/world/ib0/cone"] <= 7  # every 10 s of trial time and the last


def test_a_calibrations_recording_adds_exactly_the_entities_docs_viewer_names(tmp_path):
    trial, calibration = documented()[:2]
    schedule = default_schedule()
    steps = list(schedule.dwells) + list(schedule.plateaus)
    viewer = TrialViewer(ViewerOptions("save", layout="calibration"), tmp_path, geometry=TableGeometry(), blocking=True)
    viewer.log_table(np.array([0.0]), np.zeros((1, 3)))
    viewer.log_calibration_step(0.0, 0, steps)
    viewer.log_calibration_window(30.0, [100.0, -20.0, 5.0], [0.01, 0.02, -0.03])
    viewer.close()
    recorded = _recorded(tmp_path / "recording.rrd")
    assert recorded - trial == calibration


def test_the_rrd_gets_each_entitys_rows_as_one_chunk_every_two_minutes_of_trial_time(tmp_path):
    viewer = TrialViewer(ViewerOptions("save"), tmp_path, geometry=TableGeometry(), blocking=True)
    t = np.arange(0.0, 300.0, 0.01)
    angles = np.column_stack((np.sin(t), np.cos(t), t)) * 0.1
    for start in range(0, len(t), 100):  # a call a second, as a live trial makes them
        viewer.log_table(t[start:start + 100], angles[start:start + 100])
    viewer.close()
    reader = RrdReader(tmp_path / "recording.rrd")
    (recording,) = reader.recordings()
    chunks = [(chunk.num_rows, chunk.to_record_batch().column("trial_time").cast("int64").to_numpy()[[0, -1]] / 1e9)
              for chunk in reader.stream(store=recording)
              if chunk.entity_path == "/table/angles_deg" and not chunk.is_static]
    assert trial_viewer.FILE_FLUSH_S == 120.0
    # sent after the call that reaches 120 s, 240 s of trial time, and the rest at the end
    assert [(n, first, last) for n, (first, last) in chunks] == [
        (1210, 0.0, pytest.approx(120.9)), (1200, 121.0, pytest.approx(240.9)), (590, 241.0, pytest.approx(299.9))]


def _rows(path: Path) -> dict[str, list]:
    """The non-static rows of every entity of a .rrd's recording: path -> [(trial time s, value list)], in time
    and then logging order."""
    reader = RrdReader(path)
    (recording,) = reader.recordings()
    rows: dict[str, list] = {}
    for chunk in reader.stream(store=recording):
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        column = next(n for n in batch.schema.names if n in ("Scalars:scalars", "TextDocument:text",
                                                             "Transform3D:quaternion", "LineStrips3D:strips",
                                                             "Arrows3D:vectors"))  # fmt: skip
        t = batch.column("trial_time").cast("int64").to_numpy() / 1e9
        rows.setdefault(chunk.entity_path, []).extend(zip(t, batch.column(column).to_pylist()))
    return {entity: sorted(values, key=lambda row: row[0]) for entity, values in rows.items()}


def _blueprint_views(path: Path) -> dict[str, dict]:
    """The views of a .rrd's blueprint: display name -> {origin, range (the scalar axis's, or None)}."""
    reader = RrdReader(path)
    (blueprint,) = reader.blueprints()
    views, ranges = {}, {}
    for chunk in reader.stream(store=blueprint):
        batch = chunk.to_record_batch()
        if "ViewBlueprint:display_name" in batch.schema.names:
            views[chunk.entity_path] = (batch.column("ViewBlueprint:display_name").to_pylist()[-1][0],
                                        batch.column("ViewBlueprint:space_origin").to_pylist()[-1][0])
        if chunk.entity_path.endswith("/ScalarAxis") and "ScalarAxis:range" in batch.schema.names:
            ranges[chunk.entity_path.removesuffix("/ScalarAxis")] = batch.column("ScalarAxis:range").to_pylist()[-1][0]
    return {name: {"origin": origin, "range": ranges.get(view)} for view, (name, origin) in views.items()}


def test_each_axis_has_its_estimate_band_table_reference_and_the_emulated_truth(trial_rrd):
    rows = _rows(trial_rrd)
    result = json.loads((trial_rrd.parent / "result.json").read_text())
    bias, sigma = result["estimate"]["accel_bias_ug"], result["estimate"]["accel_bias_sigma_ug"]
    for k, axis in enumerate("xyz"):
        last = {name: rows[f"/bias/{axis}/{name}"][-1][1][0]
                for name in ("estimate", "sigma3_upper", "sigma3_lower", "table_reference", "truth")}
        assert last["estimate"] == pytest.approx(bias[k], abs=1e-9)
        assert last["sigma3_upper"] - last["sigma3_lower"] == pytest.approx(6 * sigma[k], rel=1e-9)
        assert last["table_reference"] == pytest.approx(result["table_reference"]["accel_bias_ug"][k], abs=1e-9)
        assert last["truth"] == pytest.approx(result["truth"]["accel_bias_ug"][k], rel=1e-12)


def test_the_verdict_forms_as_the_trial_runs_and_ends_as_result_json_judges(trial_rrd):
    rows = _rows(trial_rrd)["/verdict"]
    texts = [value[0] for _, value in rows]
    so_far = [t for t, _ in rows[:-1]]
    assert so_far == sorted(set(so_far)) and so_far[-1] == rows[-1][0] == 60.0  # once a time, the last at the end
    result = json.loads((trial_rrd.parent / "result.json").read_text())
    judged = [m for m in measurements(result, load_config(trial_rrd.parent / "config.yaml").limits)
              if m.outcome in (PASS, FAIL)]
    assert len(texts) >= 7  # every 10 s of a 60 s trial, and the end
    assert all(text.startswith("## Verdict so far: ") for text in texts[:-1])
    assert "| `converged_at` | — | ≤ 500 s | pending |" in texts[0]
    last = texts[-1]
    assert last.startswith(f"## Verdict: {result['verdict']}\n") and result["verdict"] in (PASS, FAIL)
    assert len(judged) >= 10
    for m in judged:
        row = next(line for line in last.splitlines() if line.startswith(f"| `{m.name}` |"))
        assert row.endswith(f"| {m.outcome} |" if m.outcome == PASS else f"| **{m.outcome}** |")
        assert f"| {m.shown} {m.unit}".rstrip() in row  # the value as report.html shows it


def test_the_layout_leads_with_the_bias_and_follows_the_converged_estimate(trial_rrd):
    views = _blueprint_views(trial_rrd)
    result = json.loads((trial_rrd.parent / "result.json").read_text())
    for k, axis in enumerate("xyz"):
        estimate, sigma = result["estimate"]["accel_bias_ug"][k], result["estimate"]["accel_bias_sigma_ug"][k]
        (whole,) = [v for name, v in views.items() if name == f"bias {axis} (µg), whole trial"]
        (followed,) = [v for name, v in views.items() if name.startswith(f"bias {axis} (µg), converged")]
        assert whole == {"origin": f"/bias/{axis}", "range": None}  # autoscaled to the whole history
        low, high = followed["range"]
        assert low <= estimate - 5 * sigma and high >= estimate + 5 * sigma
        assert high - low < 25 * sigma  # a few sigma, not the transient's thousand µg
    (sigma_view,) = [v for name, v in views.items() if name.startswith("bias 1σ")]
    largest = max(result["estimate"]["accel_bias_sigma_ug"])  # the 1σ panel follows it down, its limit in view
    assert sigma_view["range"] == pytest.approx([0.0, max(3 * largest, 1.5 * 5.0)])
    assert {v["origin"] for v in views.values()} >= {"/verdict", "/world", "/sigma", "/health/frames"}


def test_a_trial_that_did_not_complete_ends_its_verdict_as_result_json_says_not_pass(trial_rrd):
    result = json.loads((trial_rrd.parent / "result.json").read_text())
    limits = load_config(trial_rrd.parent / "config.yaml").limits
    for ended, verdict in (("interrupted: SIGINT", "INTERRUPTED"), ("early: the IMU stream stopped", "ENDED EARLY")):
        text = final_markdown(judge(result | {"ended": ended}, limits))
        assert text.splitlines()[0] == f"## Verdict: {verdict}"  # never PASS or FAIL


def test_the_imus_temperature_is_logged_once_a_second_of_trial_time_as_the_pipeline_reports_it(trial_rrd):
    rows = _rows(trial_rrd)["/imu/temperature_c"]
    seen = json.loads((trial_rrd.parent / "result.json").read_text())["streams"]["imu_temperature_c"]
    times = [t for t, _ in rows]
    seconds = [int(t) for t in times]  # the first progress of each second of trial time: one a second at most
    assert seconds == sorted(set(seconds)) and times[0] < 10.0 and times[-1] >= 59.0
    assert len(rows) >= 10  # at --speed max a loaded host's reads may hold seconds of trial time each
    assert all(seen["min"] <= value[0] <= seen["max"] for _, value in rows)


class _Chamber:
    """A chamber controller that reads what it was last sent, 2 deg C short."""

    def __init__(self) -> None:
        self.set_point_c, self.closed = 25.0, False

    def set_set_point_c(self, value: float) -> None:
        self.set_point_c = value

    def temperature_c(self) -> float:
        return self.set_point_c - 2.0

    def close(self) -> None:
        self.closed = True


def test_a_chambers_set_points_and_readings_go_to_exactly_the_entities_docs_viewer_names(tmp_path):
    trial, _, chamber_paths = documented()[:3]
    viewer = TrialViewer(ViewerOptions("save"), tmp_path, geometry=TableGeometry(), blocking=True)
    controller = _Chamber()
    chamber = watched_chamber(controller, 25.0, viewer)
    viewer.log_temperature(0.5, 24.0)
    chamber.set_set_point_c(60.0)
    viewer.log_temperature(12.0, 30.0)
    assert chamber.temperature_c() == 58.0
    chamber.close()
    viewer.close()
    assert controller.set_point_c == 60.0 and controller.closed
    path = tmp_path / "recording.rrd"
    assert _recorded(path) - trial == chamber_paths == {"/chamber/set_point_c", "/chamber/reading_c"}
    rows = _rows(path)
    assert rows["/chamber/set_point_c"] == [(0.0, [25.0]), (0.5, [60.0])]
    assert rows["/chamber/reading_c"] == [(12.0, [58.0])]  # at the latest progress's trial time
    assert rows["/imu/temperature_c"] == [(0.5, [24.0]), (12.0, [30.0])]


def test_the_temperatures_have_a_panel_beside_the_bias_sigma(trial_rrd):
    views = _blueprint_views(trial_rrd)
    assert any(name.startswith("temperature (°C)") and v["origin"] == "/" for name, v in views.items())
