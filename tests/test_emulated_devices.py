"""The emulated devices on ptys: a frame checker written from docs/wire-formats.md, the framers, the truth model."""

from __future__ import annotations

import errno
import os
import struct
import threading
from pathlib import Path

import numpy as np
import pytest
import yaml
from crccheck.crc import Crc16Xmodem, Crc32Mpeg2
from tests.helpers import from_zero

from drivers.kvh1750 import Kvh1750Codec
from drivers.tts1 import Tts1Codec
from emulators.process import EmulatorRun, spawn_emulator
from emulators.simulation import Simulation
from hil.config import load_config

RATE = 200.0
LATCH_US = 50
CONFIG = {
    "trial": {"name": "emulated", "duration_s": 3.0, "rate_hz": RATE, "seed": 3},
    "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
    "turntable": from_zero({"latch_delay_us": LATCH_US, "motion": {"kind": "swing", "axes": {
        "outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
        "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
        "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 179.9999}}}}),
}


def check_kvh(frame: bytes) -> tuple[tuple[float, ...], int]:
    """Format A from the protocol text: header, 6 big-endian float32, status, sequence, int16, CRC-32/MPEG-2."""
    assert len(frame) == 36 and frame[:4] == bytes.fromhex("FE81FF55")
    assert struct.unpack(">I", frame[32:])[0] == Crc32Mpeg2.calc(frame[:32])
    values = struct.unpack(">6f", frame[4:28])
    assert frame[28] == 0x77 and frame[29] < 128
    return values, frame[29]


def check_tts1(frame: bytes) -> tuple[int, tuple[int, int, int], int]:
    """tts1 from the protocol text: 'TS', version 1, LE counter and angles, CRC-16/XMODEM over 2..21, BE."""
    assert len(frame) == 24 and frame[:3] == b"TS\x01"
    assert struct.unpack(">H", frame[22:])[0] == Crc16Xmodem.calc(frame[2:22])
    counter, o, m, i, delay = struct.unpack("<I3iH", frame[4:22])
    assert all(-180_000_000 <= a < 180_000_000 for a in (o, m, i))
    return counter, (o, m, i), delay


def read_raw(path: str, buf: bytearray) -> None:
    """Append every byte the pty delivers to ``buf`` until the emulator closes it. Plain os.read: unlike
    a serial library's open, nothing flushes the bytes that arrive while the port is being opened."""
    fd = os.open(path, os.O_RDONLY | os.O_NOCTTY)
    try:
        while True:
            try:
                chunk = os.read(fd, 65536)
            except OSError as exc:
                if exc.errno != errno.EIO:
                    raise
                return
            if not chunk:
                return
            buf += chunk
    finally:
        os.close(fd)


def run(tmp_path: Path, errors: dict | None = None, speed: str = "max") -> tuple[dict[str, bytes], object]:
    cfg = dict(CONFIG, imu=from_zero({"errors": errors or {}}))
    config = tmp_path / "emulated.yaml"
    config.write_text(yaml.safe_dump(cfg))
    proc, ports = spawn_emulator(config, tmp_path / "ports.json", EmulatorRun(speed, wait_readers=True))
    out = {k: bytearray() for k in ("imu", "turntable_data")}  # read raw: no serial-library flush on open
    threads = [threading.Thread(target=read_raw, args=(ports[k], buf)) for k, buf in out.items()]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert proc.wait(10) == 0
    return out, load_config(config)


@pytest.fixture(scope="module")
def zero_error_run(tmp_path_factory):
    return run(tmp_path_factory.mktemp("emu"))


def test_frames_pass_an_independent_checker_and_match_truth(zero_error_run):
    out, cfg = zero_error_run
    n = int(RATE * 3)
    imu, table = out["imu"], out["turntable_data"]
    assert len(imu) == 36 * n and len(table) == 24 * n
    sim = Simulation.from_config(cfg)
    t = np.arange(1, n + 1) / RATE
    truth = np.degrees(sim.truth.angles(t + LATCH_US * 1e-6)) * 1e6
    truth = (truth + 180e6) % 360e6 - 180e6
    for k in range(1, n + 1):
        _, sequence = check_kvh(imu[36 * (k - 1):36 * k])
        assert sequence == k % 128
        counter, angles, delay = check_tts1(table[24 * (k - 1):24 * k])
        assert counter == k and delay == LATCH_US
        diff = (np.array(angles) - truth[k - 1] + 180e6) % 360e6 - 180e6
        assert np.all(np.abs(diff) <= 0.5 + 1e-6), (k, diff)


def test_zero_error_increments_equal_simulation_to_float32(zero_error_run):
    out, cfg = zero_error_run
    codec = Kvh1750Codec(RATE)
    framer = codec.framer()
    samples = codec.samples(framer.feed_bytes(out["imu"]))
    assert framer.counters.corrupt == 0
    batch = next(Simulation.from_config(cfg).batches())
    assert len(samples) == len(batch)
    np.testing.assert_allclose(samples.dtheta, batch.dtheta, rtol=1.5e-7, atol=0)
    np.testing.assert_allclose(samples.dv, batch.dv, rtol=1.5e-7, atol=0)
    table = Tts1Codec().framer().feed_bytes(out["turntable_data"])
    assert table.rows["sync_counter"].tolist() == list(range(1, len(batch) + 1))
