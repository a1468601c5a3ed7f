"""The processor's outage counts are the recording's: each stream's ``outage`` events, whether or not the
device came back, and also after the trial's end."""

from __future__ import annotations

from tests.helpers import make_config

from drivers.codec import RawChunk, StreamEvent
from emulators.simulation import Simulation
from hil.pipeline.decoding import IMU, TABLE
from hil.pipeline.processor import TrialProcessor
from hil.pipeline.progress import Progress
from hil.pipeline.settings import PipelineSettings
from hil.samples import ImuSample, TableSample

RATE = 100.0


def _processor(duration: float = 60.0) -> tuple[TrialProcessor, bytes, bytes]:
    """A processor, and 10 s of IMU and table frames of a swing."""
    cfg = make_config(duration=duration, rate=RATE)
    batch = next(Simulation.from_config(cfg).batches(chunk=1000))
    processor = TrialProcessor(PipelineSettings.of(cfg), duration)
    imu, table = (PipelineSettings.of(cfg).codecs()[s] for s in (IMU, TABLE))
    imu_bytes = b"".join(imu.encode(imu.from_sample(ImuSample(k + 1, tuple(batch.dtheta[k]), tuple(batch.dv[k]))))
                         for k in range(len(batch)))
    table_bytes = b"".join(table.encode(table.from_sample(TableSample(k + 1, tuple(batch.angles[k]))))
                           for k in range(len(batch)))
    return processor, imu_bytes, table_bytes


def _outages(progress: Progress) -> tuple[int, int]:
    extra = progress.counts.extra
    return extra["imu_outages"], extra["table_outages"]


def test_an_outage_counts_whether_or_not_the_device_comes_back():
    processor, imu, table = _processor()
    processor.feed(RawChunk(TABLE, 1.0, table[: len(table) // 2]))
    processor.feed(RawChunk(IMU, 1.0, imu[: len(imu) // 2]))
    assert _outages(processor.feed(StreamEvent(IMU, 2.0, "outage", "imu: read from /dev/imu failed"))) == (1, 0)
    # the device has not come back (yet); a reconnection is not another outage
    assert _outages(processor.feed(StreamEvent(IMU, 3.0, "reconnected"))) == (1, 0)
    processor.feed(StreamEvent(IMU, 3.5, "outage", "imu: read from /dev/imu failed"))  # reconnected to nothing
    assert _outages(processor.feed(StreamEvent(TABLE, 4.0, "outage", "table: read from /dev/table failed"))) == (2, 1)
    processor.feed(StreamEvent(IMU, 5.0, "reconnected"))
    progress = processor.feed(RawChunk(IMU, 5.0, imu[len(imu) // 2:]))
    assert _outages(progress) == (2, 1)
    assert progress.health["imu"]["outages"] == 2


def test_an_outage_after_the_end_counts_as_the_recording_holds_it():
    processor, imu, table = _processor(duration=5.0)
    processor.feed(RawChunk(TABLE, 1.0, table))
    assert processor.feed(RawChunk(IMU, 1.0, imu)).complete
    processor.feed(StreamEvent(TABLE, 2.0, "outage", "table: read from /dev/table failed"))
    progress = processor.feed(StreamEvent("gps", 2.0, "outage", "gps: read from /dev/gps failed"))
    assert _outages(progress) == (0, 1)
    extra = progress.counts.extra
    assert extra["chunks_after_end"] == 2 and extra["chunks_unknown_stream"] == 0
