"""The view of ``hil noise``: the Allan deviation per sensor and axis, log-log, as it forms over the record (the
analysis of its first T/2^k, then the whole one noise.json holds), the noise terms so far, exactly the entities
docs/viewer.md names."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml
from rerun.chunk import RrdReader
from test_viewer_record import documented

from hil.cli import main
from hil.outputs.measurements import format_value


@pytest.fixture(scope="module")
def noise_out(tmp_path_factory):
    """``hil noise --viewer save`` of a simulated static 2000 s at 50 Hz."""
    tmp = tmp_path_factory.mktemp("noise")
    data = yaml.safe_load(open("configs/emulated_swing.yaml"))
    data["trial"].update(duration_s=2000.0, rate_hz=50.0, name="static-noise")
    data["turntable"]["motion"] = {"kind": "static"}
    data["output"] = {}
    data["imu"]["errors"] = {"gyro_noise_dph": [0.02] * 3, "accel_noise_ug": [40.0] * 3,
                             "gyro_random_walk_dph_per_sqrt_h": [2.0] * 3}  # fmt: skip
    config = tmp / "static.yaml"
    config.write_text(yaml.safe_dump(data))
    out = tmp / "out"
    assert main(["noise", str(config), "--out", str(out), "--viewer", "save", "--no-figures", "--no-history"]) == 0
    return out


def _rows(out) -> dict[str, list[tuple[float, dict]]]:
    """Every entity's non-static rows in noise.rrd: path -> [(record time s, {column: value})], in time order."""
    reader = RrdReader(out / "noise.rrd")
    (recording,) = reader.recordings()
    rows: dict[str, list] = {}
    for chunk in reader.stream(store=recording):
        if chunk.is_static or chunk.entity_path == "/__properties":
            continue
        batch = chunk.to_record_batch()
        t = batch.column("trial_time").cast("int64").to_numpy() / 1e9
        columns = {name: batch.column(name).to_pylist() for name in batch.schema.names if ":" in name}
        for k, time in enumerate(t):
            rows.setdefault(chunk.entity_path, []).append((time, {n: v[k] for n, v in columns.items()}))
    return {path: sorted(values, key=lambda row: row[0]) for path, values in rows.items()}


def test_the_noise_view_holds_exactly_the_entities_docs_viewer_names(noise_out):
    assert set(_rows(noise_out)) == documented()[3]


def test_the_curves_form_over_the_record_and_end_as_noise_json(noise_out):
    rows = _rows(noise_out)
    doc = json.loads((noise_out / "noise.json").read_text())
    times = [t for t, _ in rows["/allan/gyro/x"]]
    total = 2000.0
    # the record's first T/2^k (k = 8 .. 1; T/256 = 7.8 s too short for four octaves of tau at 50 Hz), then T
    assert times == pytest.approx([total / 2**k for k in range(len(times) - 1, 0, -1)] + [total], abs=0.05)
    assert len(times) >= 6
    points = [len(value["LineStrips2D:strips"][0]) for _, value in rows["/allan/gyro/x"]]
    assert points == sorted(points) and points[-1] - points[0] >= 4  # a tau joins each time the record doubles
    for sensor in ("gyro", "accel"):
        for k, axis in enumerate("xyz"):
            curve, lower, upper = (np.array(s) for s in rows[f"/allan/{sensor}/{axis}"][-1][1]["LineStrips2D:strips"])
            np.testing.assert_allclose(curve[:, 0], np.log10(doc["tau_s"]), rtol=1e-6)
            np.testing.assert_allclose(curve[:, 1], -np.log10(doc["adev"][sensor][k]), rtol=1e-6)
            assert np.all(lower[:, 1] >= curve[:, 1]) and np.all(upper[:, 1] <= curve[:, 1])  # y = -log10 ADEV


def test_the_grid_labels_every_decade_the_curves_span(noise_out):
    rows = _rows(noise_out)
    doc = json.loads((noise_out / "noise.json").read_text())
    labels = rows["/allan/gyro/grid/labels"][-1][1]["Points2D:labels"]
    tau = np.array(doc["tau_s"])
    decades = range(math.floor(np.log10(tau.min())), math.ceil(np.log10(tau.max())) + 1)
    assert [text for text in labels if text.endswith(" s")] == [f"{10.0 ** d:g} s" for d in decades]
    adev = np.array(doc["adev"]["gyro"]).ravel()
    assert f"{10.0 ** math.floor(np.log10(adev.min())):g} deg/h" in labels
    assert f"{10.0 ** math.ceil(np.log10(adev.max())):g} deg/h" in labels


def test_the_terms_so_far_end_as_noise_json_gives_them(noise_out):
    rows = _rows(noise_out)["/allan/terms"]
    doc = json.loads((noise_out / "noise.json").read_text())
    first, last = rows[0][1]["TextDocument:text"][0], rows[-1][1]["TextDocument:text"][0]
    assert first.startswith(f"## Noise terms of the first {rows[0][0]:.4g} s of 2000 s")
    assert last.startswith("## Noise terms of the first 2000 s of 2000 s")
    arw = doc["gyro"]["arw_deg_per_sqrt_h"]
    assert "| gyro `arw_deg_per_sqrt_h` | " + " | ".join(format_value(v) for v in arw) + " |" in last
    assert "| accel `ramp_ug_per_h` | — | — | — |" in last  # unresolved on a record without a ramp


def test_the_noise_view_has_its_own_layout(noise_out):
    reader = RrdReader(noise_out / "noise.rrd")
    (blueprint,) = reader.blueprints()
    names = [chunk.to_record_batch().column("ViewBlueprint:display_name").to_pylist()[-1][0]
             for chunk in reader.stream(store=blueprint)
             if "ViewBlueprint:display_name" in chunk.to_record_batch().schema.names]
    assert sorted(names) == [f"{sensor} Allan deviation ({unit}) vs tau (s), log-log, as it forms: x red, y green, "
                             "z blue, each with its interval" for sensor, unit in (("accel", "ug"), ("gyro", "deg/h"))
                             ] + ["noise terms so far"]  # fmt: skip
