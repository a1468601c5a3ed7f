"""A Rerun recording of a noise characterisation: each sensor's Allan deviation per axis with its interval,
on an ``octave`` timeline (tau = 2^octave sample periods, so the axis is log2 tau) in log10 units."""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hil.viewer.blueprint import AXES, AXIS_COLORS, band_color
from hil.viewer.trial_viewer import APPLICATION_ID

TIMELINE = "octave"
NOISE_RRD = "noise.rrd"


def save_allan(out: Path, doc: dict) -> Path:
    """Write OUT/noise.rrd from a noise.json document; returns its path."""
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
    sensors = [s for s in ("gyro", "accel") if s in doc["adev"]]
    views = [rrb.TimeSeriesView(origin=f"/allan/{s}", name=f"{s} log10 ADEV ({doc['adev_units'][s]}) vs octave of tau")
             for s in sensors]
    path = out / NOISE_RRD
    rec.save(path, default_blueprint=rrb.Blueprint(rrb.Vertical(*views), rrb.TimePanel(timeline=TIMELINE)))
    rec.send_recording_name("noise characterisation")
    octave = np.rint(np.log2(np.asarray(doc["tau_s"]) / doc["tau_s"][0])).astype(int)
    for sensor in sensors:
        for k, axis in enumerate(AXES):
            entity = f"allan/{sensor}/{axis}"
            rec.log(entity, rr.SeriesLines(names=[f"{axis}", f"{axis} lower", f"{axis} upper"],
                                           colors=[AXIS_COLORS[axis], band_color(axis), band_color(axis)]), static=True)
            columns = [doc["adev"][sensor][k], doc["ci"]["adev"][sensor]["lower"][k], doc["ci"]["adev"][sensor]["upper"][k]]
            values = np.log10(np.column_stack(columns))
            rec.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, sequence=octave)],
                             columns=rr.Scalars.columns(scalars=values).partition([3] * len(octave)))
    rec.flush()
    rec.disconnect()
    return path
