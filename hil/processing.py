"""The trial's processing chain, fed raw chunks in arrival order: framing, decoding, alignment, estimation.

It is deterministic: the same sequence of chunks and events (a live run, or its recording) gives
the same samples, the same estimator batches and so a bit-identical result. Live acquisition
(:mod:`hil.live`) and replay (:mod:`hil.replay`) differ only in where the chunks come from.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.codec import Codec, DecodeError, Framer, RawChunk, StreamEvent
from drivers.registry import imu_codec, make_codec
from hil.config import Config
from hil.estimation.online import OnlineEstimator, Snapshot
from hil.frames import Earth, TableGeometry
from hil.results import StreamCounts, build_result
from hil.samples import AlignedSample, ImuGap, ImuSample, TableSample
from hil.sync import Aligner
from hil.time_offset import TimeOffsetEstimator

IMU, TABLE = "imu", "table"


@dataclass
class StreamDecoder:
    """One stream's framer and codec, with its outage count."""

    codec: Codec
    framer: Framer = field(init=False)
    outages: int = 0

    def __post_init__(self) -> None:
        self.framer = self.codec.framer()

    def feed(self, chunk: RawChunk) -> list[ImuSample | TableSample]:
        samples = []
        for decoded in self.framer.feed_chunk(chunk):
            try:
                samples.append(self.codec.to_sample(decoded))
            except DecodeError:
                self.framer.counters.corrupt += 1
        return samples

    def event(self, event: StreamEvent) -> None:
        if event.event == "outage":
            self.outages += 1
        self.framer.reset()


class TrialProcessor:
    """Chunks in, estimator snapshots out; :meth:`result` gives the result.json document.

    With a ``duration`` (s) the trial is :attr:`complete` once the estimator has the sample that ends
    it; later chunks (the devices' last bytes, their ports closing) are counted and ignored.

    ``on_snapshot`` is called with each new snapshot and ``on_aligned`` with each batch of aligned
    samples (for the viewers); both run on the caller's thread.
    """

    def __init__(self, cfg: Config, duration: float | None = None, on_snapshot: Callable[[Snapshot], None] | None = None,
                 on_aligned: Callable[[list[AlignedSample]], None] | None = None) -> None:
        self.cfg = cfg
        self.earth = Earth.from_degrees(cfg.site.latitude_deg, cfg.site.height_m)
        self.geometry = TableGeometry.from_config(cfg.turntable)
        self.decoders = {IMU: StreamDecoder(imu_codec(cfg.imu, cfg.imu_rate_hz)),
                         TABLE: StreamDecoder(make_codec("tts1"))}
        self.aligner = Aligner(cfg.imu_rate_hz, cfg.trial.rate_hz, cfg.imu.latch_delay_us * 1e-6)
        self.estimator: OnlineEstimator | None = None
        self.time_offset = TimeOffsetEstimator(self.earth, self.geometry, cfg.imu_rate_hz)
        self.duration = duration
        self.bridged_without_table = 0
        self.unknown_chunks = 0
        self.after_end = 0
        self._on_snapshot = on_snapshot
        self._on_aligned = on_aligned

    def feed(self, item: RawChunk | StreamEvent) -> None:
        """Process one chunk or event from any stream."""
        if self.complete:
            self.after_end += 1
            return
        decoder = self.decoders.get(item.stream)
        if decoder is None:
            self.unknown_chunks += 1
            return
        if isinstance(item, StreamEvent):
            decoder.event(item)
            return
        ready: list[AlignedSample | ImuGap] = []
        for sample in decoder.feed(item):
            ready += self.aligner.add_imu(sample) if item.stream == IMU else self.aligner.add_table(sample)
        self._estimate(ready)

    def finish(self) -> None:
        """End of data: release what the aligner still holds."""
        self._estimate(self.aligner.flush())

    @property
    def complete(self) -> bool:
        """The configured duration has been processed."""
        half_sample = 0.5 / self.cfg.imu_rate_hz
        return self.duration is not None and self.trial_time >= self.duration - half_sample

    @property
    def trial_time(self) -> float:
        """Trial time (s) of the last sample the estimator has."""
        return 0.0 if self.estimator is None else self.estimator.time

    def counts(self) -> StreamCounts:
        imu, table = (self.decoders[s].framer.counters for s in (IMU, TABLE))
        extra = {
            "imu_outages": self.decoders[IMU].outages,
            "table_outages": self.decoders[TABLE].outages,
            "skipped_bytes": imu.skipped_bytes + table.skipped_bytes,
            "imu_missing": imu.missing,
            "table_missing": table.missing,
            **{f"aligner_{k}": v for k, v in self.aligner.counters.as_dict().items()},
            "bridged_without_table": self.bridged_without_table,
            "chunks_after_end": self.after_end,
            "chunks_unknown_stream": self.unknown_chunks,
        }
        return StreamCounts(imu.frames, table.frames, self.aligner.counters.aligned, imu.missing + table.missing,
                            imu.corrupt + table.corrupt, extra)

    def result(self) -> dict:
        """The result.json document (call after :meth:`finish`)."""
        if self.estimator is None:
            raise RuntimeError("no IMU sample was received: nothing to estimate")
        truth = list(self.cfg.imu.errors.accel_bias_ug) if self.cfg.imu.source == "emulator" else None
        result = build_result(self.cfg.trial.name, self.estimator, self.counts(), truth)
        offset = self.time_offset.estimate()
        result["streams"]["sync_offset_ms"] = None if offset is None else offset * 1e3
        return result

    def _estimate(self, ready: list[AlignedSample | ImuGap]) -> None:
        if not ready:
            return
        if self.estimator is None:
            self.estimator = OnlineEstimator(self.earth, self.geometry, 1.0 / self.cfg.estimator.solve_rate_hz,
                                             self.cfg.estimator.rank_tolerance, t0=self.aligner.t0)
        before = len(self.estimator.snapshots)
        run: list[AlignedSample] = []
        for item in [*ready, None]:
            if isinstance(item, AlignedSample):
                run.append(item)
                continue
            if run:
                self.estimator.update_samples(run)
                self.time_offset.add(run)
                if self._on_aligned is not None:
                    self._on_aligned(run)
                run = []
            if isinstance(item, ImuGap):
                self.bridged_without_table += not self.estimator.bridge(item)
                self.time_offset.restart()
        if self._on_snapshot is not None:
            for snap in self.estimator.snapshots[before:]:
                self._on_snapshot(snap)
