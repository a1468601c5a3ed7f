"""What the trial's pipeline publishes: one immutable :class:`Progress` after every item it takes, handed to
its listeners (the live trial, the viewer, the table's checks, a calibration's sequence) as python-can's
``Notifier`` hands each message to its ``Listener``s, and one :class:`Finished` at the end, from which the
result is built. Nobody reads the pipeline's stages: what they did is in these values."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from hil.estimation.online import OnlineEstimator, Snapshot
from hil.samples import AlignedBatch, StreamCounts

Health = Mapping[str, Mapping[str, float]]


def read_only(health: dict[str, dict[str, float]]) -> Health:
    """The per-stream figures as a read-only mapping of read-only mappings, as a :class:`Progress` holds them."""
    return MappingProxyType({stream: MappingProxyType(values) for stream, values in health.items()})


@dataclass(frozen=True)
class Taken:
    """One block the estimator took, on the trial's time line (s from its start): the samples it used, in
    runs (the gate's rejected samples cut out; NaN angles where the table had none), and the table angles
    (N, 3) rad at ``table_t`` (N,) of the block's samples that had them."""

    samples: tuple[AlignedBatch, ...]
    table_t: np.ndarray
    table_angles: np.ndarray


@dataclass(frozen=True)
class Progress:
    """The pipeline after one item (a chunk, an event, a batch).

    ``trial_time`` (s) ends the last sample aligned; ``aligned`` counts the samples aligned, ``waiting`` those
    held for the estimator's next block, ``updates`` the blocks the estimator has taken; ``complete``: the
    configured duration is processed; ``stalled``: why the trial cannot go on (every IMU sample rejected, or the
    streams cannot be paired), else None. ``frames`` the frames decoded per stream, ``counts`` result.json's
    stream counters so far, ``health`` the per-stream figures of the viewer's panel and the console (both
    read-only: a listener cannot change what the next one receives).
    ``taken`` the blocks the estimator took with this item, ``snapshots`` the solutions they gave, ``latest``
    the newest solution so far. ``time_offset_s``: the table's lag behind the IMU (s,
    :mod:`hil.pipeline.time_offset`), measured every ``offset_every_s`` of trial time when the pipeline was
    asked to, else None. ``temperature_c``: the IMU's own temperature (deg C), the mean of the last read whose
    frames reported one (None before any did).
    """

    trial_time: float
    aligned: int
    waiting: int
    updates: int
    complete: bool
    stalled: str | None
    frames: Mapping[str, int]
    counts: StreamCounts
    health: Health
    taken: tuple[Taken, ...] = ()
    snapshots: tuple[Snapshot, ...] = ()
    latest: Snapshot | None = None
    time_offset_s: float | None = None
    temperature_c: float | None = None

    def samples(self) -> list[AlignedBatch]:
        """The runs of samples the estimator took with this item, in order."""
        return [run for block in self.taken for run in block.samples]

    def with_live(self, live: Health) -> Health:
        """:attr:`health` with a live trial's own figures (queue length, latency) added, stream by stream."""
        out = {stream: dict(values) for stream, values in self.health.items()}
        for stream, values in live.items():
            out.setdefault(stream, {}).update(values)
        return read_only(out)


Listener = Callable[[Progress], None]


@dataclass(frozen=True)
class Finished:
    """The pipeline at the end of its data: the estimator with everything it took (None when no IMU sample
    reached it), result.json's ``streams``, the ``imu.calibration`` terms applied (None: none), the last
    :class:`Progress` (None: no item was fed), and the IMU's temperature (deg C, NaN: none) at each solution
    by its trial time (:class:`~hil.pipeline.temperature.TemperatureTrack`)."""

    estimator: OnlineEstimator | None
    streams: StreamCounts
    calibration_applied: dict | None
    progress: Progress | None
    temperatures: Mapping[float, float]

    @property
    def snapshots(self) -> list[Snapshot]:
        return self.estimator.snapshots if self.estimator is not None else []
