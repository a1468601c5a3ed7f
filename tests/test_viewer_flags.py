"""The IMU's health flags in the live view: the samples it flagged invalid so far, in all and by flag, logged with
the stream health to /health/flags (docs/viewer.md)."""

from __future__ import annotations

from types import MappingProxyType

from hil.samples import StreamCounts
from hil.trial.viewer_feed import flag_health
from hil.viewer.blueprint import health_entity, health_series


def test_the_flagged_samples_go_to_health_flags_in_all_and_by_flag():
    counts = StreamCounts(extra=MappingProxyType({"imu_invalid": 12, "imu_invalid_by_flag": {"gyro_x_invalid": 12,
                                                                                             "gyro_y_invalid": 3}}))
    figures = flag_health(counts)
    assert figures == {"imu": {"invalid": 12, "flag_gyro_x_invalid": 12, "flag_gyro_y_invalid": 3}}
    assert {health_entity(metric) for metric in figures["imu"]} == {"flags"}
    assert [health_series("imu", metric) for metric in figures["imu"]] == [
        "imu invalid", "imu flag gyro x invalid", "imu flag gyro y invalid"]


def test_a_pipeline_that_reads_no_flags_logs_none():
    assert flag_health(StreamCounts()) == {}
