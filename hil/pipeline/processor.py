"""The trial's processing chain: decoding, alignment, plausibility, estimation, and the result. Fed raw chunks
in arrival order (live devices, a recording) it is deterministic: the same sequence of chunks and events gives
the same samples, the same estimator batches and so a bit-identical result. Samples that need no alignment (a
simulation, a CSV of increments) enter after the aligner, in batches."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from drivers.codec import BITS_PER_BYTE, RawChunk, StreamEvent
from drivers.controllers import data_codec
from drivers.decoder import StreamDecoder
from drivers.registry import imu_codec
from hil.config import Config
from hil.estimation.online import OnlineEstimator, Snapshot
from hil.frames import Earth, TableGeometry
from hil.pipeline.aligner import Aligner
from hil.pipeline.compensation import Compensation
from hil.pipeline.motion_match import TableRotations
from hil.pipeline.plausibility import (
    RATE_MARGIN,
    GyroTableGate,
    ImuPlausibility,
    RejectionWatch,
    UnitKeys,
)
from hil.pipeline.sync_pairing import SyncPairing
from hil.pipeline.time_offset import TimeOffsetEstimator
from hil.samples import AlignedBatch, ImuGap, ImuSamples, StreamCounts, TableSamples
from hil.units import DEG

IMU, TABLE = "imu", "table"
TABLE_WAIT_S = 5.0  # s of the host's clock the IMU may run ahead of a silent table before it goes on without it
UNPACED_TABLE_WAIT_S = 120.0  # s of trial time, at --speed max (see table_wait)


def table_wait(time_scale: float | None) -> float:
    """How far (s of trial time) the IMU may run ahead of a silent table: ``TABLE_WAIT_S`` on the host's clock
    at the devices' speed. At ``--speed max`` (None) the emulated devices go as fast as the harness reads, and
    the ports' buffers alone hold seconds of trial time of one stream while the other's reader waits for the
    processor: the table is behind, not silent, so the IMU waits ``UNPACED_TABLE_WAIT_S``."""
    return UNPACED_TABLE_WAIT_S if time_scale is None else TABLE_WAIT_S * time_scale


TableCallback = Callable[[np.ndarray, np.ndarray], None]
SamplesCallback = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


class TrialProcessor:
    """Chunks (:meth:`feed`) or aligned batches (:meth:`feed_batch`) in; estimator snapshots, stream
    counts (:meth:`streams`) and health (:meth:`health`) out, as data.

    With a ``duration`` (s) the trial is :attr:`complete` once the estimator has the sample that ends
    it; later chunks (the devices' last bytes, their ports closing) are counted and ignored.
    ``time_scale`` is the emulator's speed (see :class:`drivers.decoder.StreamDecoder`).

    ``on_snapshot`` is called with each new snapshot and the stream health, ``on_table`` with the trial times (s)
    and gimbal angles (rad, (N, 3)) of the samples the estimator took (for the viewer and the motion check),
    ``on_samples`` with the trial times (N,), increments (N, 3) and angles (N, 3; NaN where the table had none)
    of each run of aligned samples the estimator took and each batch fed (the calibration's windows), all on
    the caller's thread.
    """

    def __init__(self, cfg: Config, duration: float | None = None, time_scale: float | None = 1.0,
                 on_snapshot: Callable[[Snapshot, dict], None] | None = None, on_table: TableCallback | None = None,
                 on_samples: SamplesCallback | None = None) -> None:
        self.cfg = cfg
        self.earth = Earth.from_degrees(cfg.site.latitude_deg, cfg.site.height_m)
        self.geometry = TableGeometry.from_config(cfg.turntable)
        self.decoders = {IMU: StreamDecoder(imu_codec(cfg.imu, cfg.imu_rate_hz), time_scale, cfg.read_s),
                         TABLE: StreamDecoder(data_codec(cfg.turntable, cfg.table_counts_per_frame), time_scale,
                                              cfg.read_s)}
        free_running = cfg.imu.timing.free_running or cfg.turntable.timing.free_running
        self.aligner = Aligner(cfg.imu_rate_hz, cfg.table_counter_rate_hz, cfg.imu.latch_delay_us * 1e-6,
                               table_wait_s=table_wait(time_scale), free_running=free_running)
        self.pairing = None if free_running else self._pairing(cfg, time_scale)
        max_rate = RATE_MARGIN * max(cfg.turntable.limits.rate_dps) * DEG
        self.plausibility = ImuPlausibility(cfg.imu_rate_hz, self.earth.g, max_rate)
        self.gate = GyroTableGate(self.earth, self.geometry)
        self.watch = RejectionWatch(cfg.imu_rate_hz)
        self._stalled_by: ImuPlausibility | GyroTableGate | None = None
        self._previous: tuple[float, np.ndarray | None] | None = None  # (t, angles) of the last sample taken
        self._block: list[AlignedBatch] = []  # aligned runs waiting for the estimator
        self._blocked = 0  # ... and their samples
        # half of what a live read holds (at --speed max never: blocks): a read that completes fewer adds to the next
        self._take_at = math.inf if time_scale is None else max(1, cfg.block_samples // (2 * cfg.reads_per_block))
        self._t_end = 0.0
        self.updates = 0  # blocks handed to the estimator
        self.estimator: OnlineEstimator | None = None
        self.time_offset = TimeOffsetEstimator(self.earth, self.geometry, cfg.imu_rate_hz)
        self.duration = duration
        self.bridged_without_table = 0
        self.unknown_chunks = 0
        self.after_end = 0
        self._on_snapshot = on_snapshot
        self._on_table = on_table
        self._on_samples = on_samples
        self.compensation = Compensation(cfg.imu.calibration, 1.0 / cfg.imu_rate_hz) if cfg.imu.calibration else None
        self._batched = 0  # samples fed as aligned batches
        self._batched_angles = 0  # ... of which with table angles

    def _pairing(self, cfg: Config, time_scale: float | None) -> SyncPairing:
        """The sync pairing of the two streams' counters (docs/harness.md, "Sync pairing")."""
        codec = self.decoders[IMU].codec
        rate = cfg.imu_rate_hz
        wire = (codec.frame_bytes() * BITS_PER_BYTE / cfg.imu.baudrate,  # a CAN frame's bus time: negligible
                self.decoders[TABLE].codec.frame_bytes() * BITS_PER_BYTE / cfg.turntable.baudrate)

        def rotations(counts: np.ndarray, angles: np.ndarray) -> TableRotations:
            return TableRotations(self.geometry, self.earth, rate, cfg.table_counts_per_frame, counts, angles)

        return SyncPairing(rate, cfg.table_counts_per_frame, codec.counter_modulus, time_scale, wire, rotations)

    def feed(self, item: RawChunk | StreamEvent) -> None:
        """Process one chunk or event from any stream; events reach the decoder after the end too (its outage
        count is the recording's)."""
        decoder = self.decoders.get(item.stream)
        if isinstance(item, StreamEvent) and decoder is not None:
            self._read(item.stream, decoder.flush())  # the read before the event
            decoder.event(item)
        if self.complete:
            self.after_end += 1
            return
        if decoder is None:
            self.unknown_chunks += 1
            return
        if isinstance(item, StreamEvent):
            if self.pairing is not None:
                self.pairing.event(item.stream, item.event)
            return
        self._read(item.stream, decoder.feed(item))

    def _read(self, stream: str, samples: ImuSamples | TableSamples | None) -> None:
        """One read's samples of a stream through the checks and the pairing to the aligner and the estimator."""
        if samples is None or self.complete:
            return
        if self.compensation is not None:  # imu.calibration: the IMU's terms, the table's zero offsets
            samples = self.compensation.table(samples) if stream == TABLE else self.compensation.samples(samples)
        if stream == TABLE:
            self._estimate(self._aligned(*(self.pairing.add_table(samples) if self.pairing else (samples, None))))
            return
        good = self.plausibility.ok(samples.dtheta, samples.dv)
        if not good.all():
            self._rejected(self.plausibility, len(good) - int(good.sum()))
            samples = samples.take(good)
        self._estimate(self._aligned(*(self.pairing.add_imu(samples) if self.pairing else (None, samples))))

    def _aligned(self, table: TableSamples | None, imu: ImuSamples | None) -> list[AlignedBatch | ImuGap]:
        """Paired samples to the aligner (the table's first: the IMU's find their angles); its runs."""
        ready = self.aligner.add_tables(table) if table is not None else []
        return ready + (self.aligner.add_imus(imu) if imu is not None else [])

    def feed_batch(self, batch: AlignedBatch) -> None:
        """Samples that need no alignment (a simulation's, a CSV's) straight to the estimator."""
        if self.compensation is not None:
            batch = self.compensation.batch(batch)
        if self.estimator is None:
            self._start(batch.t0)
        before = len(self.estimator.snapshots)
        self.estimator.update_many(batch)
        self._batched += len(batch)
        self._batched_angles += 0 if batch.angles is None else len(batch)
        self._t_end = float(batch.t[-1]) if len(batch) else self._t_end
        if self._on_samples is not None and len(batch):
            angles = batch.angles if batch.angles is not None else np.full((len(batch), 3), np.nan)
            self._on_samples(batch.t - self.estimator.t0, batch.dtheta, batch.dv, angles)
        if self._on_table is not None and batch.angles is not None:
            self._on_table(batch.t - self.estimator.t0, batch.angles)
        self._snapshots_from(before)

    def _start(self, t0: float) -> None:
        self.estimator = OnlineEstimator(self.earth, self.geometry, 1.0 / self.cfg.estimator.solve_rate_hz,
                                         self.cfg.estimator.rank_tolerance, t0=t0,
                                         bias_model=self.cfg.estimator.bias_model)

    def _snapshots_from(self, before: int) -> None:
        if self._on_snapshot is not None and len(self.estimator.snapshots) > before:
            health = self.health()
            for snap in self.estimator.snapshots[before:]:
                self._on_snapshot(snap, health)

    @property
    def stalled(self) -> str | None:
        """Why every IMU sample has been rejected for the last ``STALL_S`` (naming the likely config key), or
        why the streams cannot be paired, or None while samples reach the estimator."""
        if self.pairing is not None and self.pairing.failure:
            return self.pairing.failure
        if not self.watch.stalled or self._stalled_by is None:
            return None
        return (f"every IMU sample for {self.watch.run / self.cfg.imu_rate_hz:.1f} s was rejected: "
                f"{self._stalled_by.diagnosis(UnitKeys(*self.decoders[IMU].codec.unit_advice()))}")

    def _rejected(self, by: ImuPlausibility | GyroTableGate, n: int = 1) -> None:
        self.watch.rejected(n)
        self._stalled_by = by

    def finish(self) -> None:
        """End of data: release what the aligner still holds (the samples still waiting for a pairing are
        unpaired)."""
        for stream, decoder in self.decoders.items():
            self._read(stream, decoder.flush())
        ready = self._aligned(*self.pairing.flush()) if self.pairing is not None else []
        self._estimate(ready + self.aligner.flush(), final=True)
        if self.estimator is not None:
            self.estimator.finish()

    @property
    def complete(self) -> bool:
        """The configured duration has been processed."""
        half_sample = 0.5 / self.cfg.imu_rate_hz
        return self.duration is not None and self.trial_time >= self.duration - half_sample

    @property
    def aligned(self) -> int:
        """Samples aligned so far."""
        return self.aligner.counters.aligned

    @property
    def waiting(self) -> int:
        """Aligned samples held for the estimator's next block."""
        return self._blocked

    @property
    def trial_time(self) -> float:
        """Trial time (s) at the end of the last sample aligned."""
        return 0.0 if self.estimator is None else self._t_end - self.estimator.t0

    def counts(self) -> StreamCounts:
        """The stream counters so far (those of result.json but the sync offset)."""
        if self._batched:
            return StreamCounts(self._batched, self._batched_angles, self._batched)
        imu, table = (self.decoders[s].framer.counters for s in (IMU, TABLE))
        extra = {
            "imu_outages": self.decoders[IMU].outages,
            "table_outages": self.decoders[TABLE].outages,
            "skipped_bytes": imu.skipped_bytes + table.skipped_bytes,
            "imu_missing": imu.missing,
            "imu_implausible": self.plausibility.rejected,
            "imu_gated": self.gate.rejected,
            "imu_force_outliers": 0 if self.estimator is None else self.estimator.outliers,
            "table_missing": table.missing,
            "imu_unpaired": 0 if self.pairing is None else self.pairing.report.unpaired,
            **{f"aligner_{k}": v for k, v in self.aligner.counters.as_dict().items()},
            "bridged_without_table": self.bridged_without_table,
            "chunks_after_end": self.after_end,
            "chunks_unknown_stream": self.unknown_chunks,
        }
        return StreamCounts(imu.frames, table.frames, self.aligner.counters.aligned, imu.missing + table.missing,
                            imu.corrupt + table.corrupt + self.plausibility.rejected, extra)

    def streams(self) -> StreamCounts:
        """result.json's ``streams`` (call after :meth:`finish`): the counts and, for streams that were
        aligned, the sync offset between the IMU and the table found by :mod:`hil.pipeline.time_offset`."""
        counts = self.counts()
        if not self._batched:
            offset = self.time_offset.estimate() if self.estimator is not None else None
            counts.extra["sync_offset_ms"] = None if offset is None else offset * 1e3
            counts.extra["sync"] = None if self.pairing is None else self.pairing.report.as_dict()
        return counts

    def health(self) -> dict[str, dict[str, float]]:
        """Per-stream counters for the viewer's stream-health panel and the console."""
        counts = self.counts()
        if self._batched:
            return {"aligner": {"aligned": counts.aligned}}
        out: dict[str, dict[str, float]] = {}
        for name in (IMU, TABLE):
            c = self.decoders[name].counters
            out[name] = {"frames": c.frames, "corrupt": c.corrupt, "missing": c.missing,
                         "outages": counts.extra[f"{name}_outages"]}
        out["aligner"] = {"aligned": counts.aligned, "filled": counts.extra["aligner_imu_filled"],
                          "bridged": counts.extra["aligner_imu_bridged"],
                          "without_angles": counts.extra["aligner_without_angles"]}
        return out

    def _estimate(self, ready: list[AlignedBatch | ImuGap], final: bool = False) -> None:
        """Hand the samples one read has aligned to the estimator.

        At the devices' speed it takes every sample waiting once a read completes at least half of what a
        live read holds (:attr:`_take_at`), whichever stream's read aligns them; the few left waiting for a
        table frame still on the wire join the next read's. The reads, recorded one message each (a CAN
        stream's grouped by their receive times), decide the updates: a replay updates as the live run did.
        Otherwise (``--speed max``, or a silent table) it takes whole blocks of ``Config.block_samples``,
        bounded by the samples alone, so a run at ``--speed max`` gives one result however its bytes were
        read. A gap or the end closes a block early."""
        if self.estimator is None:
            if not ready:
                return
            self._start(self.aligner.t0)
        before = len(self.estimator.snapshots)
        ready = self._until_the_end(ready)
        if ready:
            last = ready[-1]
            self._t_end = float(last.t[-1]) if isinstance(last, AlignedBatch) else last.t_end
        size = self.cfg.block_samples
        take_all = final or sum(len(item) for item in ready if isinstance(item, AlignedBatch)) >= self._take_at
        for item in ready:
            if isinstance(item, AlignedBatch):
                self._block.append(item)
                self._blocked += len(item)
                if not take_all:
                    self._take(self._blocked // size * size, size)
                continue
            self._take(self._blocked, self._blocked)
            self.bridged_without_table += not self.estimator.bridge(item)
            self.time_offset.restart()
            self._previous = None if item.angles_end is None else (item.t_end, np.asarray(item.angles_end))
        if take_all:
            self._take(self._blocked, self._blocked)
        self._snapshots_from(before)

    def _take(self, n: int, block: int) -> None:
        """The estimator takes the first ``n`` samples waiting, ``block`` at a time; the rest wait."""
        if not n:
            return
        run = _joined(self._block)
        for start in range(0, n, block):
            self._update(_part(run, start, start + block))
        self._block, self._blocked = [_part(run, n, len(run))] if n < len(run) else [], len(run) - n

    def _until_the_end(self, ready: list[AlignedBatch | ImuGap]) -> list[AlignedBatch | ImuGap]:
        """``ready`` up to the configured duration (a read's samples beyond it stay in the recording only)."""
        if self.duration is None or not ready:
            return ready
        end = self.estimator.t0 + self.duration + 0.5 / self.cfg.imu_rate_hz
        kept: list[AlignedBatch | ImuGap] = []
        for item in ready:
            if isinstance(item, ImuGap):
                if item.t_end > end:
                    break
                kept.append(item)
                continue
            n = int(np.searchsorted(item.t, end, side="right"))
            if n:
                kept.append(item if n == len(item) else _part(item, 0, n))
            if n < len(item):
                break
        return kept

    def _update(self, run: AlignedBatch | None) -> None:
        if run is None or not len(run):
            return
        self.updates += 1
        for chunk in self._gated(run):
            if isinstance(chunk, ImuGap):
                self.estimator.bridge(chunk)
                self.time_offset.restart()
                continue
            known = not np.isnan(chunk.angles).any()
            self.estimator.update_many(AlignedBatch(chunk.t, chunk.dtheta, chunk.dv, chunk.angles if known else None))
            self.time_offset.add(chunk.t, chunk.dtheta, chunk.angles)
            if self._on_samples is not None:
                self._on_samples(chunk.t - self.estimator.t0, chunk.dtheta, chunk.dv, chunk.angles)
        with_angles = ~np.isnan(run.angles[:, 0])
        if with_angles.any() and self._on_table is not None:
            self._on_table(run.t[with_angles] - self.estimator.t0, run.angles[with_angles])

    def _gated(self, run: AlignedBatch) -> list[AlignedBatch | ImuGap]:
        """The run split where the gyro disagrees with the table: those samples become bridged gaps."""
        previous = self._previous
        last = run.angles[-1]
        self._previous = (float(run.t[-1]), None if np.isnan(last[0]) else last)
        if previous is None or previous[1] is None or np.isnan(run.angles).any():
            self.watch.taken()
            return [run]
        t_end, angles = run.t, run.angles
        t_start = np.concatenate(([previous[0]], t_end[:-1]))
        starts = np.vstack((previous[1], angles[:-1]))
        good = self.gate.consistent(t_start, t_end, starts, angles, run.dtheta)
        if good.any():
            self.watch.taken(len(good) - 1 - int(np.flatnonzero(good)[-1]))
        else:
            self._rejected(self.gate, len(good))
        if good.all():
            return [run]
        out: list[AlignedBatch | ImuGap] = []
        k = 0
        while k < len(good):
            if good[k]:
                stop = k + int(np.argmin(good[k:])) if not good[k:].all() else len(good)
                out.append(_part(run, k, stop))
                k = stop
            else:
                out.append(ImuGap(t_start[k], t_end[k], tuple(starts[k]), tuple(angles[k].tolist())))
                k += 1
        return out


def _part(run: AlignedBatch, start: int, stop: int) -> AlignedBatch:
    return AlignedBatch(run.t[start:stop], run.dtheta[start:stop], run.dv[start:stop], run.angles[start:stop])


def _joined(runs: list[AlignedBatch]) -> AlignedBatch | None:
    """One run of consecutive runs (None for none)."""
    if len(runs) < 2:
        return runs[0] if runs else None
    return AlignedBatch(*(np.concatenate([getattr(r, name) for r in runs]) for name in ("t", "dtheta", "dv", "angles")))
