"""The trial's pipeline: decode -> compensate -> judge -> pair -> align -> block -> gate -> estimate, one stage
a module (docs/architecture.md, "The stages and the hops of a live read"). Fed raw chunks in arrival order
(live devices, a recording) it is deterministic: the same sequence of chunks and events gives the same samples,
the same estimator blocks and so a bit-identical result. Samples that need no alignment (a simulation, a CSV of
increments) enter at the estimate stage, in batches. After every item it publishes one
:class:`~hil.pipeline.progress.Progress` to its listeners and returns it; at the end of data, one
:class:`~hil.pipeline.progress.Finished`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from types import MappingProxyType

import numpy as np

from drivers.codec import BITS_PER_BYTE, RawChunk, StreamEvent
from hil.frames import Earth, TableGeometry
from hil.pipeline.aligner import Aligner
from hil.pipeline.blocks import Blocks, Released, until
from hil.pipeline.compensation import Compensation
from hil.pipeline.decoding import IMU, TABLE, Decoding, Samples
from hil.pipeline.estimate import Estimation
from hil.pipeline.judge import Judge
from hil.pipeline.motion_match import TableRotations
from hil.pipeline.progress import Finished, Health, Listener, Progress, Taken, read_only
from hil.pipeline.settings import PipelineSettings
from hil.pipeline.sync_pairing import SyncPairing
from hil.pipeline.temperature import TemperatureTrack
from hil.samples import AlignedBatch, ImuGap, ImuSamples, StreamCounts, TableSamples
from hil.units import DEG_PER_H

TABLE_WAIT_S = 5.0  # s of the host's clock the IMU may run ahead of a silent table before it goes on without it
UNPACED_TABLE_WAIT_S = 120.0  # s of trial time, at --speed max (see table_wait)


def table_wait(time_scale: float | None) -> float:
    """How far (s of trial time) the IMU may run ahead of a silent table: ``TABLE_WAIT_S`` on the host's clock
    at the devices' speed. At ``--speed max`` (None) the emulated devices go as fast as the harness reads, and
    the ports' buffers alone hold seconds of trial time of one stream while the other's reader waits for the
    processor: the table is behind, not silent, so the IMU waits ``UNPACED_TABLE_WAIT_S``."""
    return UNPACED_TABLE_WAIT_S if time_scale is None else TABLE_WAIT_S * time_scale


class TrialProcessor:
    """Chunks and events (:meth:`feed`) or aligned batches (:meth:`feed_batch`) in, one :class:`Progress` per
    item out (returned, and handed to each of ``listeners``); :meth:`finish` at the end of the data.

    With a ``duration`` (s) the trial is complete once the estimator has the sample that ends it; later chunks
    (the devices' last bytes, their ports closing) are counted and ignored. ``time_scale`` is the emulator's
    speed (see :class:`drivers.decoder.StreamDecoder`). With ``offset_every_s`` the table's lag behind the IMU
    is measured every that many seconds of trial time (:attr:`Progress.time_offset_s`).
    """

    def __init__(self, settings: PipelineSettings, duration: float | None = None, time_scale: float | None = 1.0,
                 listeners: Sequence[Listener] = (), offset_every_s: float | None = None) -> None:
        s = settings
        self._rate_hz = s.imu_rate_hz
        self._decoding = Decoding(s, time_scale)
        self._compensation = Compensation(s.imu.calibration, 1.0 / s.imu_rate_hz) if s.imu.calibration else None
        self._judge = Judge(s.earth, s.geometry, s.imu_rate_hz, s.rate_limit_dps,
                            self._decoding.codec(IMU).health_flags, s.estimator.gyro_table_gate,
                            s.estimator.flags_end_trial)
        self._pairing = None if s.free_running else sync_pairing(s, time_scale, self._decoding)
        self._aligner = Aligner(s.imu_rate_hz, s.table_counter_rate_hz, s.imu.latch_delay_us * 1e-6,
                               table_wait_s=table_wait(time_scale), free_running=s.free_running)
        self._blocks = Blocks.of(s, time_scale)
        self._estimation = Estimation(s)
        self._listeners = tuple(listeners)
        self._duration = duration
        self._offset_every = offset_every_s
        self._next_offset = offset_every_s
        self._offset: float | None = None
        self._t_end = 0.0
        self._batched = [0, 0]  # samples fed as aligned batches, and of those with table angles
        self._ignored = {"chunks_after_end": 0, "chunks_unknown_stream": 0}
        self._step: tuple[int, list[Taken]] = (0, [])  # the step's first snapshot, and the blocks it took
        self._last: Progress | None = None

    def feed(self, item: RawChunk | StreamEvent) -> Progress:
        """One chunk or event from any stream; events reach the decoder after the end too (its outage count is
        the recording's)."""
        self._begin()
        known = self._decoding.knows(item.stream)
        if isinstance(item, StreamEvent) and known:
            self._estimate(self._read(item.stream, self._decoding.event(item)))  # the read before the event
        if self._complete():
            self._ignored["chunks_after_end"] += 1
        elif not known:
            self._ignored["chunks_unknown_stream"] += 1
        elif isinstance(item, StreamEvent):
            if self._pairing is not None:
                self._pairing.event(item.stream, item.event)
        else:
            self._estimate(self._read(item.stream, self._decoding.chunk(item)))
        return self._publish()

    def feed_batch(self, batch: AlignedBatch) -> Progress:
        """Samples that need no alignment (a simulation's, a CSV's) straight to the estimate stage."""
        self._begin()
        self._decoding.temperature.add(batch.temperature_c)
        if self._compensation is not None:
            batch = self._compensation.batch(batch)
        if self._estimation.estimator is None:
            self._estimation.start(batch.t0)
        self._step[1].append(self._estimation.batch(batch))
        self._batched[0] += len(batch)
        self._batched[1] += len(batch) if batch.has_angles else 0
        self._t_end = float(batch.t[-1]) if len(batch) else self._t_end
        return self._publish()

    def skip(self, gap: ImuGap) -> None:
        """Samples a simulation did not make (a soak's wait): the estimator, started at the gap's start if it has
        not, carries its attitude across with the table's readings at both ends; nothing is published."""
        if self._estimation.estimator is None:
            self._estimation.start(gap.t_start)
        self._estimation.gap(gap)
        self._t_end = gap.t_end

    def finish(self) -> Finished:
        """End of data: release what the stages still hold (the samples still waiting for a pairing are
        unpaired), keep the estimator's final solution, and publish the last progress."""
        self._begin()
        for stream, samples in self._decoding.flush():
            self._estimate(self._read(stream, samples))
        ready = self._aligned(*self._pairing.flush()) if self._pairing is not None else []
        self._estimate(ready + self._aligner.flush(), final=True)
        if self._estimation.estimator is not None:
            self._estimation.estimator.finish()
        self._publish()
        return self.finished()

    def finished(self) -> Finished:
        """What the pipeline has so far, as :meth:`finish` gives it, without ending it: a batch-fed pipeline's
        result (its estimator keeps no final solution)."""
        streams = self._counts()
        if not self._batched[0]:
            offset, rate_error = self._estimation.time_offset_s(), self._estimation.gyro_rate_error()
            streams = replace(streams, extra=MappingProxyType({
                **streams.extra, "sync_offset_ms": None if offset is None else offset * 1e3,
                "gyro_rate_error_dph": None if rate_error is None else (rate_error / DEG_PER_H).tolist(),
                "sync": None if self._pairing is None else self._pairing.report.as_dict()}))
        applied = self._compensation.applied if self._compensation is not None else None
        return Finished(self._estimation.estimator, streams, applied, self._last, self._decoding.temperature.at)

    def _read(self, stream: str, samples: Samples | None) -> list[Released]:
        """One read's samples of a stream through compensation, the plausibility check and the pairing to the
        aligner: the runs and gaps it releases."""
        if samples is None or self._complete():
            return []
        if self._compensation is not None:  # imu.calibration: the IMU's terms, the table's zero offsets
            samples = self._compensation.table(samples) if stream == TABLE else self._compensation.samples(samples)
        if stream == TABLE:
            paired = self._pairing.add_table(samples) if self._pairing else (samples, None)
        else:
            samples = self._judge.plausible(samples)
            paired = self._pairing.add_imu(samples) if self._pairing else (None, samples)
        return self._aligned(*paired)

    def _aligned(self, table: TableSamples | None, imu: ImuSamples | None) -> list[Released]:
        """Paired samples to the aligner (the table's first: the IMU's find their angles); its runs."""
        ready = self._aligner.add_tables(table) if table is not None else []
        return ready + (self._aligner.add_imus(imu) if imu is not None else [])

    def _estimate(self, ready: list[Released], final: bool = False) -> None:
        """What one read released, up to the trial's end, through the block stage and the gate to the estimator."""
        if self._estimation.estimator is None:
            if not ready:
                return
            self._estimation.start(self._aligner.t0)
        if self._duration is not None and ready:
            ready = until(ready, self._estimation.estimator.t0 + self._duration + 0.5 / self._rate_hz)
        if ready:
            last = ready[-1]
            self._t_end = float(last.t[-1]) if isinstance(last, AlignedBatch) else last.t_end
        for item in self._blocks.add(ready, final):
            if isinstance(item, ImuGap):
                self._estimation.gap(item)
                self._judge.after_gap(item)
            else:
                self._step[1].append(self._estimation.block(item, self._judge.gated(item)))

    def _trial_time(self) -> float:
        """Trial time (s) at the end of the last sample aligned."""
        estimator = self._estimation.estimator
        return 0.0 if estimator is None else self._t_end - estimator.t0

    def _complete(self) -> bool:
        """The configured duration has been processed."""
        return self._duration is not None and self._trial_time() >= self._duration - 0.5 / self._rate_hz

    def _begin(self) -> None:
        estimator = self._estimation.estimator
        self._step = (0 if estimator is None else len(estimator.snapshots), [])

    def _publish(self) -> Progress:
        """This step's :class:`Progress`, to every listener."""
        estimator = self._estimation.estimator
        snapshots = estimator.snapshots if estimator is not None else []
        trial_time = self._trial_time()
        if self._next_offset is not None and trial_time >= self._next_offset:
            self._offset = self._estimation.time_offset_s()
            self._next_offset = trial_time + self._offset_every
        self._decoding.temperature.solved([s.t for s in snapshots[self._step[0]:]])
        counts = self._counts()
        stalled = self._decoding.imu_rate.mismatch or (self._pairing.failure if self._pairing is not None else None)
        health = _health(self._decoding, counts, bool(self._batched[0]))
        progress = Progress(trial_time, self._aligner.counters.aligned, self._blocks.waiting, self._estimation.updates,
                            self._complete(), stalled or self._judge.stalled(self._decoding.unit_keys()),
                            self._decoding.frames(), counts, health, tuple(self._step[1]),
                            tuple(snapshots[self._step[0]:]), snapshots[-1] if snapshots else None, self._offset,
                            self._decoding.temperature.latest)
        for listener in self._listeners:
            listener(progress)
        self._last = progress
        return progress

    def _counts(self) -> StreamCounts:
        """The stream counters so far (those of result.json but the sync offset)."""
        if self._batched[0]:
            return StreamCounts(*self._batched, self._batched[0], extra=_temperature(self._decoding.temperature))
        imu, table = (self._decoding.counters(s) for s in (IMU, TABLE))
        estimator = self._estimation.estimator
        extra = {
            "imu_outages": self._decoding.outages(IMU),
            "table_outages": self._decoding.outages(TABLE),
            "skipped_bytes": imu.skipped_bytes + table.skipped_bytes,
            "imu_missing": imu.missing,
            **self._judge.counts(),
            "imu_temperature_c": self._decoding.temperature.summary(),
            "imu_force_outliers": 0 if estimator is None else estimator.outliers,
            "table_missing": table.missing,
            "imu_unpaired": 0 if self._pairing is None else self._pairing.report.unpaired,
            **{f"aligner_{k}": v for k, v in self._aligner.counters.as_dict().items()},
            "bridged_without_table": self._estimation.bridged_without_table,
            **self._ignored,
        }
        return StreamCounts(imu.frames, table.frames, self._aligner.counters.aligned, imu.missing + table.missing,
                            imu.corrupt + table.corrupt + self._judge.plausibility.rejected, MappingProxyType(extra))


def sync_pairing(settings: PipelineSettings, time_scale: float | None, decoding: Decoding) -> SyncPairing:
    """The pair stage: the sync pairing of the two streams' counters (docs/harness.md, "Sync pairing")."""
    s, codec = settings, decoding.codec(IMU)
    wire = (codec.frame_bytes() * BITS_PER_BYTE / s.imu.baudrate,  # a CAN frame's bus time: negligible
            decoding.codec(TABLE).frame_bytes() * BITS_PER_BYTE / s.turntable.baudrate)

    def rotations(counts: np.ndarray, angles: np.ndarray) -> TableRotations:
        return TableRotations(s.geometry, s.earth, s.imu_rate_hz, s.table_counts_per_frame, counts, angles)

    return SyncPairing(s.imu_rate_hz, s.table_counts_per_frame, codec.counter_modulus, time_scale, wire, rotations,
                       s.estimator.pair_by_motion)


def _health(decoding: Decoding, counts: StreamCounts, batched: bool) -> Health:
    """Per-stream counters for the viewer's stream-health panel and the console."""
    if batched:
        return read_only({"aligner": {"aligned": counts.aligned}})
    out = {}
    for name in (IMU, TABLE):
        c = decoding.counters(name)
        out[name] = {"frames": c.frames, "corrupt": c.corrupt, "missing": c.missing,
                     "outages": counts.extra[f"{name}_outages"]}
    out["aligner"] = {"aligned": counts.aligned, "filled": counts.extra["aligner_imu_filled"],
                      "bridged": counts.extra["aligner_imu_bridged"],
                      "without_angles": counts.extra["aligner_without_angles"]}
    return read_only(out)


def _temperature(track: TemperatureTrack) -> MappingProxyType:
    """A batched trial's detailed counts: the temperature a simulated IMU with a thermal model reports."""
    seen = track.summary()
    return MappingProxyType({} if seen is None else {"imu_temperature_c": seen})
