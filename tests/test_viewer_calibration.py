"""The calibration's Rerun views: the schedule's progress on the 3-D table and each window's residual as it is
measured, read back from the saved recording."""

from __future__ import annotations

import itertools
import json
import math
import queue
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from rerun.chunk import RrdReader
from test_calibrate_trial import IMU_ERRORS, calibration_config
from test_calibration import body_from_n, paper_c_pa

from hil.cli import main
from hil.estimation.calibration_schedule import Dwell, default_schedule
from hil.frames import Earth, TableGeometry
from hil.units import ARCSEC, DEG, G0, PPM, UG
from hil.viewer import calibration_view, log_jobs
from hil.viewer.modes import ViewerOptions
from hil.viewer.trial_viewer import TrialViewer

MARKERS = "/" + calibration_view.MARKERS


def _rows(path: Path, entity: str, column: str) -> list[tuple[float, object]]:
    """(trial time s, value) of every timed row of one component of one entity, in time order."""
    rows = []
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if chunk.is_static or chunk.entity_path != entity or column not in batch.schema.names:
            continue
        t = batch.column("trial_time").cast("int64").to_numpy() / 1e9
        rows += list(zip(t, batch.column(column).to_pylist(), strict=True))
    return sorted(rows, key=lambda r: r[0])


def _bars(value: list[dict]) -> list[float]:
    """The values of one BarChart row (a tensor: shape, buffer)."""
    return list(value[0]["buffer"])


def _rgb(packed: int) -> tuple[int, int, int]:
    return (packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255


def test_progress_markers_steps_and_residuals_are_logged_as_given(tmp_path):
    schedule = default_schedule()
    steps = list(schedule.dwells) + list(schedule.plateaus)
    viewer = TrialViewer(ViewerOptions("save", layout="calibration"), tmp_path, geometry=TableGeometry(), blocking=True)
    viewer.log_calibration_step(0.0, 0, steps)
    viewer.log_calibration_window(30.0, [100.0, -20.0, 5.0], [0.01, 0.02, -0.03])
    viewer.log_calibration_step(30.0, 1, steps)
    viewer.log_calibration_window(60.0, [7.0, 8.0, 9.0], [0.04, 0.05, 0.06])
    viewer.log_calibration_step(60.0, 18, steps)
    viewer.log_calibration_window(100.0, None, [1.0, 2.0, 3.0])  # a plateau: gyros only
    viewer.close()
    assert viewer.error is None and viewer.dropped == 0
    path = tmp_path / "recording.rrd"

    assert [(t, v) for t, v in _rows(path, "/calibration/step", "Scalars:scalars")] == [
        (0.0, [1.0, 24.0]), (30.0, [2.0, 24.0]), (60.0, [19.0, 24.0])]
    texts = [v[0] for _, v in _rows(path, "/calibration/log", "TextLog:text")]
    first, second, plateau = schedule.dwells[0], schedule.dwells[1], schedule.plateaus[0]
    gimbal = ("outer", "middle", "inner")[plateau.axis]
    assert texts == ["step 1 of 24: position 1 at ({:g}, {:g}, {:g}) deg".format(*np.array(first.angles) / DEG),
                     "step 2 of 24: position 2 at ({:g}, {:g}, {:g}) deg".format(*np.array(second.angles) / DEG),
                     f"step 19 of 24: plateau 1: {gimbal} at {plateau.rate / DEG:g} deg/s"]

    # each position's marker sits straight below the IMU when the table is at that position
    (_, markers), = [r for r in _rows(path, MARKERS, "Points3D:positions") if r[0] == 0.0]
    markers = np.array(markers)
    assert markers.shape == (18, 3)
    for k, dwell in enumerate(schedule.dwells):
        world = body_from_n(np.array(dwell.angles)).T @ markers[k]  # C_b^n, independent of the viewer's geometry
        assert world == pytest.approx([0.0, 0.0, -calibration_view.MARKER_RADIUS], abs=1e-6)
    colors = {t: [_rgb(c) for c in v] for t, v in _rows(path, MARKERS, "Points3D:colors")}
    assert colors[30.0][:3] == [calibration_view.DONE, calibration_view.CURRENT, calibration_view.PENDING]
    assert colors[60.0] == [calibration_view.DONE] * 18  # on the plateaus every position is done

    assert _rows(path, "/calibration/residual/accel_ug", "Scalars:scalars") == [
        (30.0, [100.0, -20.0, 5.0]), (60.0, [7.0, 8.0, 9.0])]
    gyro = _rows(path, "/calibration/residual/gyro_dph", "Scalars:scalars")
    assert [t for t, _ in gyro] == [30.0, 60.0, 100.0] and gyro[2][1] == [1.0, 2.0, 3.0]
    # a bar per position measured so far
    assert [_bars(v) for _, v in _rows(path, "/calibration/bars/x", "BarChart:values")] == [[100.0], [100.0, 7.0]]
    assert _bars(_rows(path, "/calibration/bars/z", "BarChart:values")[-1][1]) == [5.0, 9.0]


def _true_force_residual(angles, zero):
    """The specific force of Eq. (6) with the emulated errors at the true angles, minus gravity at the encoder's."""
    errors = {"bias": np.array(IMU_ERRORS["accel_bias_ug"]) * UG,
              "scale": np.array(IMU_ERRORS["accel_scale_ppm"]) * PPM,
              "mis": np.array(IMU_ERRORS["accel_misalignment_arcsec"]) * ARCSEC,
              "knl": np.array(IMU_ERRORS["accel_nonlinearity_ug_per_g2"]) * UG / G0**2}
    g = Earth.from_degrees(32.0, 10.0).g
    true = body_from_n(angles + zero) @ [0.0, 0.0, g]
    v = np.diag(1.0 + errors["scale"]) @ paper_c_pa(*errors["mis"]) @ true
    return v + errors["knl"] * v**2 + errors["bias"] - body_from_n(angles) @ [0.0, 0.0, g]


class _FullForLiveCalls(queue.Queue):
    """A logging queue that a live (non-blocking) call always finds full, as a viewer fallen behind does."""

    def put(self, item, block=True, timeout=None):
        if not block:
            raise queue.Full
        super().put(item, block, timeout)


def test_a_live_viewer_fallen_behind_still_logs_every_calibration_step_and_window(tmp_path, monkeypatch):
    steps = list(default_schedule().dwells)
    monkeypatch.setattr(log_jobs, "queue", SimpleNamespace(Queue=_FullForLiveCalls, Full=queue.Full))
    viewer = TrialViewer(ViewerOptions("save", layout="calibration"), tmp_path,
                         geometry=TableGeometry())  # live: never blocks
    viewer.log_table(np.array([0.0]), np.zeros((1, 3)))  # a live call: dropped and counted
    viewer.log_calibration_step(0.0, 0, steps)
    viewer.log_calibration_window(30.0, [100.0, -20.0, 5.0], [0.01, 0.02, -0.03])
    viewer.close()
    path = tmp_path / "recording.rrd"
    assert viewer.dropped == 1
    assert _rows(path, "/calibration/step", "Scalars:scalars") == [(0.0, [1.0, 18.0])]
    assert _rows(path, "/calibration/residual/gyro_dph", "Scalars:scalars") == [(30.0, [0.01, 0.02, -0.03])]


@pytest.mark.slow
def test_an_emulated_calibration_logs_every_step_and_each_windows_residual_as_it_is_measured(tmp_path, capsys):
    config = calibration_config(tmp_path, positions=6, dwell_s=2, plateau_s=3)
    out = tmp_path / "out"
    code = main(["calibrate", str(config), "--speed", "max", "--viewer", "save", "--out", str(out), "--quiet",
                 "--no-figures"])
    assert code in (0, 3), capsys.readouterr().err  # six positions leave terms unobservable; judged or not
    path = out / "recording.rrd"
    schedule = default_schedule(positions=6)
    steps = [(float(t), v) for t, v in _rows(path, "/calibration/step", "Scalars:scalars")]
    assert [v for _, v in steps] == [[float(k), 12.0] for k in range(1, 13)]
    assert steps[0][0] == 0.0 and all(b[0] > a[0] for a, b in itertools.pairwise(steps))
    accel = _rows(path, "/calibration/residual/accel_ug", "Scalars:scalars")
    gyro = _rows(path, "/calibration/residual/gyro_dph", "Scalars:scalars")
    assert len(accel) == 6 and len(gyro) == 12
    # a dwell's residual is logged when its window closes: after its step began, before the next one
    for k, (t, _) in enumerate(accel):
        assert steps[k][0] < t <= steps[k + 1][0] + 1e-9
    zero = np.array([35.0, 30.0, -20.0]) * ARCSEC
    noise = 50.0 / math.sqrt(2 * 200)  # ug: 50 ug a sample over a 2 s dwell at 200 Hz
    for (_, value), dwell in zip(accel, schedule.dwells, strict=True):
        assert isinstance(dwell, Dwell)
        expected = _true_force_residual(np.array(dwell.angles), zero) / UG
        assert np.abs(np.array(value) - expected) == pytest.approx(np.zeros(3), abs=5 * noise), (value, expected)
    # the plateaus' gyro residual is the scale error times the rate, far above the dwells' earth-rate residual
    assert min(np.max(np.abs(v)) for _, v in gyro[6:]) > 10 * max(np.max(np.abs(v)) for _, v in gyro[:6])
    bars = _rows(path, "/calibration/bars/y", "BarChart:values")
    assert _bars(bars[-1][1]) == pytest.approx([v[1] for _, v in accel])


def test_a_calibration_over_temperature_logs_the_chambers_set_points_and_readings_and_the_imus_temperature(tmp_path):
    out = tmp_path / "out"
    assert main(["calibrate", "configs/calibration_thermal_quick.yaml", "--simulate", "--out", str(out), "--viewer",
                 "save"]) == 0  # fmt: skip
    rrd = out / "recording.rrd"
    set_points = [value[0] for _, value in _rows(rrd, "/chamber/set_point_c", "Scalars:scalars")]
    assert set_points == [-10.0, 25.0, 60.0]  # each soak's, sent as it starts
    readings = _rows(rrd, "/chamber/reading_c", "Scalars:scalars")
    imu = _rows(rrd, "/imu/temperature_c", "Scalars:scalars")
    assert len(readings) >= 10 and len(imu) >= 10
    assert min(v[0] for _, v in readings) < -5.0 and max(v[0] for _, v in readings) > 55.0  # the chamber's swings
    thermal = json.loads((out / "calibration.json").read_text())["thermal"]["temperatures"]
    # the IMU's temperature reaches each point's mean, as the soak waited for it
    assert all(any(abs(v[0] - point["imu_c"]) < 0.2 for _, v in imu) for point in thermal)
