"""What the processing hands to viewers: snapshots, gimbal angles and stream health, live or in replay."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from hil.estimation.online import Snapshot
from hil.pipeline.processor import IMU, TABLE, TrialProcessor
from hil.samples import AlignedSample


class Viewer(Protocol):
    """What a trial needs of a viewer (see :class:`hil.viewer.rerun_viewer.TrialViewer`)."""

    def log_snapshot(self, snap: Snapshot) -> None: ...
    def log_table(self, t: np.ndarray, angles: np.ndarray) -> None: ...
    def log_health(self, t: float, health: dict[str, dict[str, float]]) -> None: ...
    def close(self) -> None: ...


def health(processor: TrialProcessor) -> dict[str, dict[str, float]]:
    """Per-stream counters for the viewer's stream-health panel."""
    counts = processor.counts()
    out: dict[str, dict[str, float]] = {}
    for name in (IMU, TABLE):
        c = processor.decoders[name].framer.counters
        out[name] = {"frames": c.frames, "corrupt": c.corrupt, "missing": c.missing,
                     "outages": counts.extra[f"{name}_outages"]}
    out["aligner"] = {"aligned": counts.aligned, "filled": counts.extra["aligner_imu_filled"],
                      "bridged": counts.extra["aligner_imu_bridged"],
                      "without_angles": counts.extra["aligner_without_angles"]}
    return out


class ViewerSinks:
    """The processor's callbacks, forwarding to a viewer (or nowhere); ``extra_health`` adds live figures."""

    def __init__(self, viewer: Viewer | None, extra_health: Callable[[], dict[str, dict[str, float]]] | None = None
                 ) -> None:
        self.viewer = viewer
        self.extra_health = extra_health
        self.processor: TrialProcessor | None = None

    def on_snapshot(self, snap: Snapshot) -> None:
        if self.viewer is None or self.processor is None:
            return
        self.viewer.log_snapshot(snap)
        figures = health(self.processor)
        if self.extra_health is not None:
            for stream, values in self.extra_health().items():
                figures.setdefault(stream, {}).update(values)
        self.viewer.log_health(snap.t, figures)

    def on_aligned(self, samples: list[AlignedSample]) -> None:
        with_angles = [s for s in samples if s.angles is not None]
        if self.viewer is None or self.processor is None or not with_angles:
            return
        t0 = self.processor.estimator.t0
        self.viewer.log_table(np.array([s.t - t0 for s in with_angles]),
                              np.array([s.angles for s in with_angles], dtype=float))
