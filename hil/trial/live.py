"""A live trial: device readers, the recorder, and the processing loop with its sinks.

Threads: one reader per device (:class:`drivers.reader.DeviceReader`) hands every raw chunk to a
:class:`Fanout`, which stamps it with the host time rounded to the recording's nanoseconds and puts
it, in one global order, into the recorder's queue (unbounded: the recording never drops) and into
the bounded processing queue. The caller's thread runs the :class:`~hil.pipeline.processor.TrialProcessor`
on that queue, its listeners (viewer, the table's checks) on each :class:`~hil.pipeline.progress.Progress` it
publishes, and the console at display rate, so neither the viewer nor
the disk can hold up acquisition. A full processing queue makes the readers wait (the serial
driver's buffers hold the bytes): nothing is lost, and the live result stays equal to the replay's.
"""

from __future__ import annotations

import dataclasses
import queue
import sys
import threading
import time
from dataclasses import dataclass
from collections.abc import Callable
from pathlib import Path


from drivers.codec import RawChunk, StreamEvent, check_baudrate
from drivers.reader import DeviceReader
from drivers.tap import RawListener
from hil.config import Config
from hil.estimation.online import Snapshot
from hil.outputs.record import RecordSource, start_record
from hil.outputs.result import COMPLETED, TrialEnd
from hil.pipeline.decoding import IMU, TABLE
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.progress import Finished, Health, Listener, Progress
from hil.pipeline.settings import PipelineSettings
from hil.pipeline.stream_watch import StreamWatch
from hil.trial.imu_config import check_imu_config
from hil.trial.latency_stats import LatencyStats
from hil.trial.rig import DataLinks
from hil.recording.recorder import Recorder, to_ns
from hil.trial.table_control import MotionCheck
from hil.trial.viewer_feed import Viewer, ViewerFeed

QUEUE_ITEMS = 20_000  # ~25 s of chunks at 200 Hz x 2 streams (and more, as chunks hold several frames)
SYNC_CHECK_S = 10.0  # trial s between the checks of the streams' lag (a cross-correlation over up to 60 s of data)
TABLE_WATCHDOG_S = 1.0  # no data from a table the harness commands for this long stops it
START_TIMEOUT_S = 15.0  # the first data must arrive within this
SETTLE_S = 0.5  # after the devices' process has ended, the readers' last chunks arrive within this
END_TOLERANCE_S = 1.0  # frames lost at the very end: the trial still counts as complete


class TrialAborted(RuntimeError):
    """The trial could not go on (no data, the devices went away); outputs hold what was received."""


class Fanout(RawListener):
    """Orders chunks from all readers once, for the recorder and for processing."""

    def __init__(self, recorder: Recorder, hand_off: queue.Queue) -> None:
        self._recorder = recorder
        self._queue = hand_off
        self._lock = threading.Lock()
        self._closed = False
        self.last_arrival = 0.0  # monotonic time of the last chunk with data
        self.last_by_stream: dict[str, float] = {}

    def on_raw(self, chunk: RawChunk) -> None:
        self._put(dataclasses.replace(chunk, host_time=to_ns(chunk.host_time) / 1e9))
        self.last_arrival = self.last_by_stream[chunk.stream] = time.monotonic()

    def on_event(self, event: StreamEvent) -> None:
        self._put(dataclasses.replace(event, host_time=to_ns(event.host_time) / 1e9))

    def _put(self, item: RawChunk | StreamEvent) -> None:
        with self._lock:
            if self._closed:
                return
            self._recorder.write(item)
            self._queue.put(item)

    def close(self, drain: Callable[[], None]) -> None:
        """Take nothing more (a reader shared with other trials goes on), with ``drain`` emptying the queue
        meanwhile: a hand-over waiting for room completes before this returns."""
        self._closed = True
        drain()
        with self._lock:  # the last hand-over, if one was under way
            pass
        drain()


def _warn(text: str) -> None:
    print(f"hil: WARNING: {text}", file=sys.stderr)


@dataclass(frozen=True)
class TrialHooks:
    """What a runner plugs into a :class:`LiveTrial`; every field optional.

    ``motion_check``: the harness commands the table; it listens to the pipeline (``on_progress``), and the
    trial ends when its ``failure`` says the table does not move as commanded, or when the table's data stops
    for ``TABLE_WATCHDOG_S`` (the caller then turns the table off).
    ``on_progress`` gets the trial time, the latest snapshot and the health about twice a second;
    ``on_warning`` a warning line. ``source_done`` is polled: True (the emulator process has exited) with the
    data stopped ends the trial, complete if it reached the duration within ``END_TOLERANCE_S``.
    ``stop_requested`` is polled every step: a signal name ends the trial as interrupted. ``on_end`` is
    called the moment acquisition ends, however it ends, before the backlog is processed: where the table is
    turned off. ``listeners`` listen to the pipeline besides (:class:`~hil.pipeline.progress.Progress`).
    ``finished`` is polled every step: True ends the trial as completed (a trial whose length is set by what the
    harness commands).
    ``queue_items`` bounds the processing queue: a small one holds the emulated devices close behind the
    processing (the table then answers a command without lag). ``early_end`` is polled every step: a reason ends
    the trial early (a calibration's soak that did not settle). ``table_reader``: the table's reader, shared by the
    trials of several units on one table (docs/units.md); its owner starts and stops it, and this trial listens
    to it until it ends, when a stream silent for ``output.outage_limit_s`` ends it too.
    """

    motion_check: MotionCheck | None = None
    on_progress: Callable[[float, Snapshot | None, dict], None] | None = None
    on_warning: Callable[[str], None] = _warn
    source_done: Callable[[], bool] = lambda: False
    stop_requested: Callable[[], str | None] = lambda: None
    on_end: Callable[[], None] = lambda: None
    listeners: tuple[Listener, ...] = ()
    finished: Callable[[], bool] = lambda: False
    queue_items: int = QUEUE_ITEMS
    early_end: Callable[[], str | None] = lambda: None
    table_reader: DeviceReader | None = None


@dataclass(frozen=True)
class LiveSettings:
    """What a live trial takes from its one-unit config, read once by :meth:`of`: the pipeline's settings, the
    table's frame rate (``trial.rate_hz``), ``output.outage_limit_s`` and the source of its record."""

    pipeline: PipelineSettings
    table_rate_hz: float
    outage_limit_s: float
    record: RecordSource

    @classmethod
    def of(cls, cfg: Config) -> LiveSettings:
        """The live settings of a one-unit config."""
        return cls(PipelineSettings.of(cfg), cfg.trial.rate_hz, cfg.output.outage_limit_s, RecordSource.of(cfg))


class LiveTrial:
    """Acquire, record and estimate from ``links`` (:meth:`hil.trial.rig.Rig.links`, opened by its readers) until
    the duration is reached, the devices stop, or a stop signal, with the runner's :class:`TrialHooks`.

    ``time_scale`` is the emulator's speed. An outage of every device shorter than ``output.outage_limit_s``
    is ridden out (the readers reconnect), a longer one ends the trial early. A trial whose IMU samples are
    all rejected for ``STALL_S`` ends early with the processor's diagnosis, and one whose stream's bytes arrive
    for ``output.stream_timeout_s`` without a frame with the :class:`StreamWatch`'s line (the port, and what
    the bytes decode as).
    """

    def __init__(self, settings: LiveSettings, config_text: str, out: Path, duration: float | None, links: DataLinks,
                 viewer: Viewer | None = None, time_scale: float | None = 1.0, hooks: TrialHooks = TrialHooks()
                 ) -> None:
        self.settings = settings
        self.hooks = hooks
        self.sync_warned = False
        self.out = out
        self.duration = duration
        self.viewer = viewer
        self.interrupted: str | None = None
        self.latency = LatencyStats()
        self.ended_by_source = False
        self.acquiring = True  # until acquisition ends: the motion check then no longer listens (the table is off)
        self.progress: Progress | None = None  # the pipeline's, after the last item it took
        self.finished: Finished | None = None  # ... and at the end
        listeners = [ViewerFeed(viewer, self._live_health).on_progress, *hooks.listeners]
        if hooks.motion_check is not None:
            listeners.append(self._check_motion)
        pipeline = settings.pipeline
        self.processor = TrialProcessor(pipeline, duration, time_scale, listeners, offset_every_s=SYNC_CHECK_S)
        gather = pipeline.read_s if time_scale is not None else 0.0  # at --speed max a read holds plenty anyway
        shared = hooks.table_reader
        opened = links.transports
        codecs = pipeline.codecs()
        if opened[IMU].byte_stream:  # a real port's line too (the emulator checks its own)
            check_baudrate(IMU, codecs[IMU].frame_bytes(), pipeline.imu_rate_hz, pipeline.imu.baudrate)
        check_baudrate("turntable", codecs[TABLE].frame_bytes(), settings.table_rate_hz, pipeline.turntable.baudrate)
        self.stream_watch = StreamWatch.of(pipeline, {s: t.address for s, t in opened.items()})
        imu_config = check_imu_config(codecs[IMU], opened[IMU], hooks.on_warning)
        self.recorder = Recorder(out / "recording.mcap", config_text, duration=duration, time_scale=time_scale,
                                 record=start_record(settings.record, config_text, links.recorded_ports(), imu_config))
        self.queue: queue.Queue = queue.Queue(hooks.queue_items)
        self.fanout = Fanout(self.recorder, self.queue)
        self.readers = [DeviceReader(t, raw_listeners=[self.fanout], gather_s=gather) for t in opened.values()
                        if shared is None or t is not shared.transport]
        if shared is not None:
            shared.raw_listeners = [*shared.raw_listeners, self.fanout]  # a new list: the reader may be iterating

    def run(self) -> str:
        """Run to the end; how it ended: ``completed``, ``early: <reason>`` or ``interrupted: <signal>``; the
        pipeline's end in :attr:`finished`.

        Raises :class:`~drivers.transport.TransportError` (after closing everything) when a port cannot
        be opened at the start; the trial then leaves no recording.
        """
        ended = TrialEnd.early("the trial did not start")  # str(ended) is result.json's "ended"
        started = False
        try:
            for reader in self.readers:
                reader.start()
            started = True
            try:
                self._loop()
            except TrialAborted as exc:
                ended = TrialEnd.early(exc)
            else:
                ended = TrialEnd.interrupted(self.interrupted) if self.interrupted else TrialEnd(COMPLETED)
            return str(ended)
        finally:
            self.acquiring = False
            self.hooks.on_end()
            for reader in self.readers:
                reader.stop()
            self._leave_shared()
            self._drain()
            if started:
                self.recorder.close(str(ended))
            else:
                self.recorder.discard()
            self.finished = self.processor.finish()
            if self.viewer is not None:
                self.viewer.close()

    def _drain(self) -> None:
        """Process what the readers handed over last: the replay sees it too."""
        while not self.queue.empty():
            self.processor.feed(self.queue.get_nowait())

    def _leave_shared(self) -> None:
        """Stop listening to the shared table reader, which goes on for the other units."""
        shared = self.hooks.table_reader
        if shared is not None:
            shared.raw_listeners = [listener for listener in shared.raw_listeners if listener is not self.fanout]
            self.fanout.close(self._drain)

    def _check_motion(self, progress: Progress) -> None:
        """The motion check's listener while the table is commanded: the backlog processed after the table is
        turned off is not checked, nor commanded on from (its port is closed)."""
        if self.acquiring:
            self.hooks.motion_check.on_progress(progress)

    def _live_health(self) -> Health:
        """The live trial's own figures (queue length, latency), added to the pipeline's health."""
        return {"aligner": {"queue": self.queue.qsize(), **self.latency.percentiles_ms()}}

    def _loop(self) -> None:
        started = time.monotonic()
        next_progress = started
        while not ((self.progress is not None and self.progress.complete) or self.ended_by_source
                   or self.hooks.finished()):
            self.interrupted = self.hooks.stop_requested()
            if self.interrupted:
                return
            try:
                item = self.queue.get(timeout=0.05)
            except queue.Empty:
                item = None
            if item is not None:
                self._took(item, self.processor.feed(item))
            now = time.monotonic()
            if now >= next_progress and self.progress is not None:
                next_progress = now + 0.5
                if self.hooks.on_progress is not None:
                    p = self.progress
                    self.hooks.on_progress(p.trial_time, p.latest, p.with_live(self._live_health()))
            if item is None and self.queue.empty():
                self._check_alive(now, started)

    def _took(self, item: RawChunk | StreamEvent, progress: Progress) -> None:
        """What the pipeline published for an item: the checks that end the trial, the stream watch, the
        latency, and the lag between the streams (warned of once, as soon as it shows: :func:`lag_warning`)."""
        updates = self.progress.updates if self.progress is not None else 0
        self.progress = progress
        if self.hooks.motion_check is not None and self.hooks.motion_check.failure:
            raise TrialAborted(f"turntable is not moving as commanded: {self.hooks.motion_check.failure}")
        if progress.stalled or self.hooks.early_end():
            raise TrialAborted(progress.stalled or self.hooks.early_end())
        if isinstance(item, StreamEvent):
            self.stream_watch.event(item)
        elif item.stream in progress.frames:
            verdict = self.stream_watch.fed(item, progress.frames[item.stream])
            if verdict:
                raise TrialAborted(verdict)
        if isinstance(item, RawChunk):
            self.latency.fed(item.host_time, progress.aligned)
            if progress.updates != updates:
                self.latency.updated(progress.waiting)
        warning = None if self.sync_warned else lag_warning(progress.time_offset_s, self.settings.pipeline.imu_rate_hz)
        if warning is not None:
            self.sync_warned = True
            self.hooks.on_warning(warning)

    def _trial_time(self) -> float:
        return self.progress.trial_time if self.progress is not None else 0.0

    def _check_alive(self, now: float, started: float) -> None:
        last = self.fanout.last_arrival
        near_end = self.duration is not None and self._trial_time() >= self.duration - END_TOLERANCE_S
        # the data has ended: the devices stopped at the end (its last frames may be lost), or the
        # emulator's process is gone and the readers have handed over its last bytes
        if now - last > SETTLE_S and ((last and near_end) or self.hooks.source_done()):
            self.ended_by_source = True
            if not near_end and self.duration is not None:
                raise TrialAborted(f"the emulated devices stopped at {self._trial_time():.1f} s "
                                   f"of {self.duration:.1f} s")
            return
        if last == 0.0 and now - started > START_TIMEOUT_S:
            raise TrialAborted(f"no data from the devices within {START_TIMEOUT_S:.0f} s")
        table_last = self._last_arrival(TABLE, now)
        if self.hooks.motion_check is not None and table_last and now - table_last > TABLE_WATCHDOG_S:
            raise TrialAborted(f"watchdog: no data from the commanded turntable for {TABLE_WATCHDOG_S:.0f} s")
        limit = self.settings.outage_limit_s
        if self.hooks.table_reader is not None:
            self._check_streams(now - started, now, limit)
        if last and now - last > limit:
            why = "; ".join(reader.down for reader in self.readers if reader.down)
            message = f"no data from any device for {limit:g} s (output.outage_limit_s)"
            raise TrialAborted(f"{message}: {why}" if why else message)


    def _last_arrival(self, stream: str, now: float) -> float | None:
        """When the stream's last chunk arrived (monotonic s; None: none yet); ``now`` while the shared table
        reader is handing a chunk over (another unit's full queue holds it up: the table is not silent)."""
        shared = self.hooks.table_reader
        last = self.fanout.last_by_stream.get(stream)
        return now if last and shared is not None and stream == TABLE and shared.handing_over else last

    def _check_streams(self, since_start: float, now: float, limit: float) -> None:
        """A trial of one of several units: its IMU, or the table, silent for ``limit`` s (or from the start for
        ``START_TIMEOUT_S``) ends it; the other units' streams keep its fan-out busy."""
        for reader in (*self.readers, self.hooks.table_reader):
            stream, address = reader.transport.stream, reader.transport.address
            last = self._last_arrival(stream, now)
            why = f": {reader.down}" if reader.down else ""
            if last and now - last > limit:
                raise TrialAborted(f"no data from the {stream} ({address}) for {limit:g} s (output.outage_limit_s)"
                                   f"{why}")
            if not last and since_start > START_TIMEOUT_S:
                raise TrialAborted(f"no data from the {stream} ({address}) within {START_TIMEOUT_S:.0f} s{why}")


def lag_warning(offset: float | None, rate_hz: float) -> str | None:
    """The console's warning of a lag ``offset`` (s) of the table's angles behind the IMU beyond one IMU period: the
    sync wiring or a latch delay is wrong, and every estimate of the trial with it (``output.limits.
    sync_offset_ms_max`` judges it at the end); None within a period, or unmeasured."""
    period = 1.0 / rate_hz
    if offset is None or abs(offset) <= period:
        return None
    return (f"the table's angles lag the IMU by {offset * 1e3:.2f} ms, more than one IMU period ({period * 1e3:.2f} "
            "ms): check the sync pulse wiring and imu.latch_delay_us")
