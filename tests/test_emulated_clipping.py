"""An emulated IMU whose gyros read their range (``imu.errors.gyro_range_dps``) raises its codec's clip flags on
those axes, as an MTi's StatusWord does (bits 11-13), so the harness never estimates with a clipped sample; a codec
without clip flags (the KVH 1750) sends its healthy status."""

from __future__ import annotations

import numpy as np
from lab_form import emulated

from drivers.decoder import StreamDecoder
from drivers.registry import imu_codec
from emulators.reads import emulated_reads
from hil.config import parse_config
from hil.units import DEG

RANGE_DPS = 6.0  # the swing turns the IMU's y and z axes faster than this, its x axis at 4 deg/s at most


def _decoded(protocol: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The emulated IMU's samples over 8 s: increments (N, 3) rad, status words, and each axis's raised clip flag
    (N, 3) by the codec's own reading."""
    cfg = parse_config(emulated(200.0, protocol=protocol, duration_s=8.0, errors={"gyro_range_dps": RANGE_DPS}))
    codec = imu_codec(cfg.imu, 200.0)
    decoder = StreamDecoder(codec)
    batches = [decoder.feed(chunk) for chunk in emulated_reads(cfg, 8.0) if chunk.stream == "imu"]
    samples = [b for b in batches if b is not None and len(b)]
    dtheta = np.concatenate([s.dtheta for s in samples])
    status = np.concatenate([s.status for s in samples])
    flags = {f.name: f for f in codec.health_flags}
    raised = np.stack([flags[name].raised(status) for name in codec.clip_flags], axis=1) if codec.clip_flags \
        else np.zeros((len(status), 3), bool)
    return dtheta, status, raised


def test_an_mti_reading_its_gyro_range_raises_the_clipping_flag_of_that_axis_alone():
    dtheta, _, raised = _decoded("xsens-mtdata2")
    at_range = np.isclose(np.abs(dtheta), RANGE_DPS * DEG / 200.0, rtol=1e-6)
    assert at_range[:, 1:].sum(axis=0).min() > 100 and not at_range[:, 0].any()
    assert np.array_equal(raised, at_range)


def test_a_kvh_has_no_clip_flag_and_sends_its_healthy_status():
    dtheta, status, _ = _decoded("kvh1750")
    assert np.isclose(np.abs(dtheta), RANGE_DPS * DEG / 200.0, rtol=1e-6).any()
    assert set(status.tolist()) == {0x77}
