"""Rerun logging: the saved recording holds the trial's values under the documented entity paths."""

from __future__ import annotations

import os
import subprocess
import threading
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from tests.helpers import PAPER_ERRORS, make_config
from rerun.chunk import RrdReader

from emulators.simulation import Simulation
from hil.config import ReportLimits
from hil.estimation.online import OnlineEstimator
from hil.units import DEG, UG
from hil.viewer import blueprint, log_jobs, rerun_process, trial_viewer
from hil.viewer.bias_view import BiasTruth, follow_ranges
from hil.viewer.verdict import PENDING, VerdictSoFar
from hil.viewer.modes import default_viewer_mode
from hil.viewer.modes import ViewerOptions
from hil.viewer.trial_viewer import TrialViewer

HEALTH = {  # the pipeline's figures and a live trial's
    "imu": {"frames": 12000, "corrupt": 1, "missing": 2, "outages": 0},
    "table": {"frames": 12000, "corrupt": 0, "missing": 0, "outages": 1},
    "aligner": {"aligned": 11990, "filled": 3, "bridged": 0, "without_angles": 4, "queue": 2,
                "latency_p50_ms": 3.25, "latency_p99_ms": 7.5, "latency_max_ms": 12.0, "age_p50_ms": 4.0,
                "age_p99_ms": 8.0, "age_max_ms": 15.5, "table_lag_ms": 0.004},
}
HEALTH_ENTITIES = {  # entity: its series, in order of appearance
    "/health/frames": [("imu", "frames"), ("table", "frames"), ("aligner", "aligned")],
    "/health/faults": [(s, m) for s in ("imu", "table") for m in ("corrupt", "missing", "outages")]
                      + [("aligner", m) for m in ("filled", "bridged", "without_angles")],
    "/health/queue": [("aligner", "queue")],
    "/health/latency_ms": [("aligner", f"{m}_{p}_ms") for m in ("latency", "age") for p in ("p50", "p99", "max")],
    "/health/sync_ms": [("aligner", "table_lag_ms")],  # a panel of its own, not among the latencies
}


@pytest.fixture(scope="module")
def trial():
    """A 60 s emulated swing at 100 Hz: snapshots at 1 Hz, table angles of every sample."""
    cfg = make_config(duration=60.0, rate=100.0, errors=PAPER_ERRORS)
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0)
    batches = list(sim.batches(chunk=1000))
    for batch in batches:
        est.update_many(batch)
    return sim, est.snapshots, batches


def _series(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every scalar entity of a .rrd: path -> (trial time s (N,), values (N, series)), read with the rerun SDK."""
    rows: dict[str, list] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if chunk.is_static or "Scalars:scalars" not in batch.schema.names:
            continue
        t = batch.column(blueprint.TIMELINE).cast("int64").to_numpy() / 1e9
        values = batch.column("Scalars:scalars").to_pylist()
        rows[chunk.entity_path].extend(zip(t, values))
    out = {}
    for entity, pairs in rows.items():
        pairs.sort()
        out[entity] = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs], dtype=float))
    return out


def _entities(path: Path) -> dict[str, int]:
    rows: dict[str, int] = defaultdict(int)
    for chunk in RrdReader(path).stream():
        rows[chunk.entity_path] += chunk.num_rows
    return rows


@pytest.fixture(scope="module")
def saved(trial, tmp_path_factory):
    sim, snapshots, batches = trial
    out = tmp_path_factory.mktemp("viz")
    truth = np.array(PAPER_ERRORS["accel_bias_ug"]) * UG
    viewer = TrialViewer(ViewerOptions("save"), out, geometry=sim.truth.geometry, truth=BiasTruth(truth), blocking=True)
    viewer.log_snapshots(snapshots[:30])
    for snap in snapshots[30:]:  # the live path, one at a time
        viewer.log_snapshot(snap)
    for batch in batches:
        viewer.log_table(batch.t, batch.angles)
    for k in range(1, 61):
        viewer.log_health(float(k), HEALTH)
    viewer.close()
    assert viewer.dropped == 0 and viewer.error is None
    return out / "recording.rrd", snapshots


def test_saved_recording_holds_bias_sigma_rank_alignment_and_health(saved):
    path, snapshots = saved
    series = _series(path)
    final = snapshots[-1]
    bias, sigma = final.full.bias / UG, final.full.bias_sigma / UG
    table = final.table_bias / UG
    for k, axis in enumerate("xyz"):
        expected = {"estimate": bias[k], "sigma3_lower": bias[k] - 3 * sigma[k], "sigma3_upper": bias[k] + 3 * sigma[k],
                    "table_reference": table[k], "truth": PAPER_ERRORS["accel_bias_ug"][k]}
        for name, value in expected.items():
            t, values = series[f"/bias/{axis}/{name}"]  # one series an entity
            assert t[-1] == pytest.approx(final.t)
            assert values[-1, 0] == pytest.approx(value, rel=1e-12)
    assert abs(table[0] - PAPER_ERRORS["accel_bias_ug"][0]) < 20.0  # the table's reference, not another estimate
    assert series["/sigma"][1][-1] == pytest.approx(sigma, rel=1e-12)
    # bias rows exist only where the bias was observable, one per such snapshot
    observable = [s for s in snapshots if s.full.bias is not None]
    assert len(series["/bias/x/estimate"][0]) == len(observable) < len(snapshots)

    t, rank = series["/observability/rank"]  # 12-state, 9-state
    assert len(t) == len(snapshots) and rank[0, 0] < 12
    assert list(rank[-1]) == [12, final.gravity_only.observability.rank]
    cond = series["/observability/log10_condition"][1][-1, 0]
    assert cond == pytest.approx(np.log10(final.full.observability.condition))

    for k, angle in enumerate(("pitch", "roll", "yaw")):
        values = series[f"/alignment/{angle}"][1][-1]  # method 1, method 2[, theoretical]
        expected = [final.error_method1[k], final.error_method2[k]]
        if angle != "yaw":
            expected.append(final.error_theoretical[k])
        assert values == pytest.approx(np.array(expected) / DEG, rel=1e-12)

    assert {path for path in series if path.startswith("/health/")} == set(HEALTH_ENTITIES)
    for path, names in HEALTH_ENTITIES.items():
        t, values = series[path]  # one series per stream and metric, in order of appearance
        assert len(t) == 60 and t[-1] == 60.0
        assert values[-1].tolist() == [HEALTH[stream][metric] for stream, metric in names]


def test_a_real_devices_bias_has_its_table_reference_no_truth_and_the_limits_drawn(trial, tmp_path):
    sim, snapshots, _ = trial
    limits = ReportLimits(bias_sigma_ug_max=5.0, converged_by_s=30.0)
    viewer = TrialViewer(ViewerOptions("save"), tmp_path, geometry=sim.truth.geometry, blocking=True, limits=limits)
    viewer.log_snapshots(snapshots)
    viewer.close()
    series = _series(tmp_path / "recording.rrd")
    assert not any(path.endswith("/truth") for path in _entities(tmp_path / "recording.rrd"))
    for axis in "xyz":
        assert {f"/bias/{axis}/{name}" for name in ("estimate", "sigma3_upper", "sigma3_lower", "table_reference")} \
            <= set(series)
    t, limit = series["/sigma/limit"]
    assert len(t) == len(snapshots) and set(limit[:, 0]) == {5.0}
    t, marker = series["/sigma/converged_by"]  # a vertical line at the deadline, the height of the 1σ panel
    assert list(t) == [30.0, 30.0]
    assert list(marker[:, 0]) == [0.0, pytest.approx(np.nanmax(series["/sigma"][1][series["/sigma"][0] <= 30.0]))]


def test_a_batched_trial_gets_its_verdict_so_far_once_at_its_end(trial, tmp_path):
    sim, snapshots, _ = trial
    viewer = TrialViewer(ViewerOptions("save"), tmp_path, geometry=sim.truth.geometry, blocking=True,
                         limits=ReportLimits(bias_sigma_ug_max=5.0))
    viewer.log_snapshots(snapshots)  # simulate and replay: every snapshot in one call
    viewer.close()
    times = [chunk.to_record_batch().column(blueprint.TIMELINE).cast("int64").to_numpy() / 1e9
             for chunk in RrdReader(tmp_path / "recording.rrd").stream() if chunk.entity_path == "/verdict"]
    assert np.concatenate(times).tolist() == [60.0]


def test_the_verdict_so_far_waits_for_values_and_fails_a_convergence_past_its_deadline(trial):
    _, snapshots, _ = trial
    verdict = VerdictSoFar(ReportLimits(bias_sigma_ug_max=50.0, converged_by_s=30.0, bias_error_ug_max=10.0),
                           np.array(PAPER_ERRORS["accel_bias_ug"], dtype=float))
    outcome = lambda: {m.name: m.outcome for m in verdict.measurements() if m.limit}  # noqa: E731
    assert outcome()["accel_bias_sigma_x"] == PENDING and outcome()["converged_at"] == PENDING
    verdict.add([s for s in snapshots if s.t <= 20.0])
    assert outcome()["converged_at"] == PENDING  # not converged, before its deadline
    assert outcome()["accel_bias_sigma_x"] in ("PASS", "FAIL")
    verdict.add([s for s in snapshots if s.t > 20.0])
    assert verdict.result()["estimate"]["converged_at_s"] is None  # 60 s at 100 Hz: 3σ above 10 µg
    assert outcome()["converged_at"] == "FAIL"
    assert "| `accel_bias_error_x` |" in verdict.markdown() and "\\|x\\| ≤ 10 µg" in verdict.markdown()
    assert verdict.markdown().startswith("## Verdict so far: FAIL (trial running, 60 s)")


def test_a_calibrations_fitted_figures_are_pending_while_it_runs(trial):
    _, snapshots, _ = trial
    limits = ReportLimits(calibration_residual_ug_max=20.0, calibration_error_sigma_max=4.0)
    verdict = VerdictSoFar(limits, np.array(PAPER_ERRORS["accel_bias_ug"], dtype=float), calibration=True)
    verdict.add(snapshots)
    judged = {m.name: (m.limit, m.outcome) for m in verdict.measurements() if m.limit}
    assert judged["calibration_residual_max"] == ("≤ 20", PENDING)
    assert judged["calibration_error_worst"] == ("≤ 4", PENDING)


def test_the_followed_bias_view_spans_a_few_sigma_about_the_latest_estimate(trial):
    _, snapshots, _ = trial
    final = snapshots[-1]
    ranges = follow_ranges(final)
    for k, axis in enumerate("xyz"):
        estimate, sigma = final.full.bias[k] / UG, final.full.bias_sigma[k] / UG
        low, high = ranges[axis]
        assert low <= estimate - 5 * sigma and high >= estimate + 5 * sigma and high - low <= 12 * sigma
    far = np.array([1e4, 1e4, 1e4]) * UG  # a truth 10 mg away is left out of the followed view
    assert follow_ranges(final, far) == follow_ranges(final)
    assert follow_ranges(snapshots[0]) is None  # no bias yet: the view autoscales


def test_table_angles_are_decimated_for_the_3d_view(saved, trial):
    path, _ = saved
    _, _, batches = trial
    t, angles = _series(path)["/table/angles_deg"]
    assert len(t) == 60 * trial_viewer.TABLE_RATE_HZ + 1  # one per 100 ms tick from 0.01 s to 60 s
    assert t[0] == pytest.approx(0.01) and np.diff(t)[1:] == pytest.approx(1.0 / trial_viewer.TABLE_RATE_HZ)
    k = np.searchsorted(batches[-1].t, t[-1])
    assert angles[-1] == pytest.approx(batches[-1].angles[k] / DEG)
    entities = _entities(path)
    for gimbal in ("outer", "outer/middle", "outer/middle/inner"):
        assert entities[f"/world/table/{gimbal}"] == len(t)
    assert 6 <= entities["/world/ib0/cone"] <= 7  # redrawn every 10 s of trial time, and the last
    assert {"/world/table/outer/middle/inner/imu/case", "/world/ib0"} <= set(entities)


def test_saved_recording_carries_the_blueprint_and_passes_rrd_verify(saved, tmp_path):
    path, _ = saved
    reader = RrdReader(path)
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    env = dict(os.environ, CI="1", HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path), XDG_DATA_HOME=str(tmp_path))
    proc = subprocess.run([rerun_process.rerun_executable(), "rrd", "verify", str(path)], check=False, env=env,
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "verified without error" in proc.stdout + proc.stderr


def test_live_calls_never_wait_for_a_stalled_logging_thread(trial, tmp_path, monkeypatch):
    sim, snapshots, _ = trial
    monkeypatch.setattr(log_jobs, "QUEUE_ITEMS", 4)
    viewer = TrialViewer(ViewerOptions("save"), tmp_path, geometry=sim.truth.geometry)
    release = threading.Event()
    viewer._submit(release.wait)  # the logging thread is stuck in this job
    for k in range(50):  # a call that waited would wait for ever: the logging thread is held until after
        viewer.log_health(float(k), HEALTH)
        viewer.log_snapshot(snapshots[-1])
    release.set()
    viewer.close()
    assert viewer.dropped >= 100 - 4
    assert (tmp_path / "recording.rrd").exists()


def test_mode_none_writes_nothing_and_unknown_modes_are_refused(trial, tmp_path):
    sim, snapshots, batches = trial
    viewer = TrialViewer(ViewerOptions("none"), tmp_path / "none", geometry=sim.truth.geometry)
    viewer.log_snapshots(snapshots)
    viewer.log_table(batches[0].t, batches[0].angles)
    viewer.log_health(1.0, HEALTH)
    viewer.close()
    assert not (tmp_path / "none").exists()
    with pytest.raises(ValueError, match="spawn, serve, save, none"):
        TrialViewer(ViewerOptions("web"), tmp_path, geometry=sim.truth.geometry)


def test_default_mode_spawns_only_with_a_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert default_viewer_mode() == "save"
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    assert default_viewer_mode() == "spawn"


def _listening(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp) listening on ``port``."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not os.path.exists(table):
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.split(":")
            if state == "0A" and int(hex_port, 16) == port:
                found.add(address)
    return found


@pytest.mark.skipif(not os.path.exists("/proc/net/tcp"), reason="needs Linux /proc/net/tcp")
def test_serve_mode_binds_loopback_prints_the_url_and_keeps_analytics_off(trial, tmp_path, capsys):
    sim, snapshots, _ = trial
    viewer = TrialViewer(ViewerOptions("serve"), tmp_path, geometry=sim.truth.geometry)
    try:
        viewer.log_snapshots(snapshots[:5])
        viewer.close()
        url = viewer.url
        assert url.startswith("http://127.0.0.1:") and "url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A" in url
        assert url in capsys.readouterr().err
        web_port = int(url.split(":")[2].split("/")[0])
        grpc_port = int(url.split("%3A")[2].split("%2F")[0])
        for port in (web_port, grpc_port):
            assert _listening(port) == {"0100007F"}  # 127.0.0.1 only
        environ = Path(f"/proc/{viewer.viewer_process.pid}/environ").read_bytes().split(b"\0")
        assert b"CI=1" in environ or any(e.startswith(b"CI=") for e in environ)
    finally:
        viewer.stop()
    assert viewer.viewer_process is None
    t, _ = _series(tmp_path / "recording.rrd")["/observability/rank"]  # the file has its own stream
    assert t.tolist() == [s.t for s in snapshots[:5]]
