"""What many test modules share: configs of the paper's swing, an estimator run, independent attitudes from
scipy, decoding listeners and small process helpers (the fixtures live in conftest.py)."""

import numpy as np
from scipy.spatial.transform import Rotation

from drivers.decoder import StreamDecoder
from drivers.tap import RawListener
from emulators.simulation import Simulation
from hil.config import Config, parse_config
from hil.estimation.online import OnlineEstimator

SWING = {
    "outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
    "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
    "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6},
}
PAPER_ERRORS = {
    "accel_bias_ug": [60, 150, 260],
    "accel_noise_ug": [50, 50, 50],
    "gyro_bias_dph": [0.01, 0.01, 0.01],
    "gyro_noise_dph": [0.01, 0.01, 0.01],
}


def make_config(duration=60.0, rate=100.0, kind="swing", errors=None, seed=1, turntable=None) -> Config:
    table = {"motion": {"kind": kind, "axes": SWING}}
    table.update(turntable or {})
    return parse_config(
        {
            "trial": {"name": "test", "duration_s": duration, "rate_hz": rate, "seed": seed},
            "site": {"latitude_deg": 32.0, "longitude_deg": 118.0},
            "turntable": table,
            "imu": {"errors": errors or {}},
        }
    )


def run_estimator(cfg: Config, solve_period=10.0, geometry=None) -> OnlineEstimator:
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, geometry or sim.truth.geometry, solve_period=solve_period)
    for batch in sim.batches():
        est.update_many(batch)
    est.finish()
    return est


class Decoding(RawListener):
    """A device reader's raw listener that keeps every chunk and decodes them as the processor does."""

    def __init__(self, codec) -> None:
        self.decoder = StreamDecoder(codec)
        self.raw: list = []
        self.samples: list = []
        self.events: list = []
        self.stopped = False

    @property
    def counters(self):
        return self.decoder.counters

    def on_raw(self, chunk) -> None:
        self.raw.append(chunk)
        self.samples += self.decoder.feed(chunk).records()

    def on_event(self, event) -> None:
        self.events.append(event)
        self.decoder.event(event)

    def stop(self) -> None:
        self.stopped = True


def scipy_attitude(geometry, angles: np.ndarray) -> Rotation:
    """C_b^n = C_table^n Rz(outer) Rx(middle) Ry(inner) C_b^mount from scipy's rotations, independent of hil.frames."""
    table = Rotation.from_rotvec([geometry.tilt[0], geometry.tilt[1], 0.0]) * Rotation.from_euler("z", geometry.azimuth)
    return table * Rotation.from_euler("ZXY", angles) * Rotation.from_euler("ZXY", geometry.mounting)


def earth_turn(earth, t) -> Rotation:
    """C_n^n0(t) from scipy: the turn by omega_ie t about the earth axis."""
    return Rotation.from_rotvec(np.outer(np.atleast_1d(np.asarray(t, dtype=float)), earth.omega_n))


def true_attitude_ib0(truth, t: np.ndarray) -> Rotation:
    """C_b^ib0(t) = C_n^b(0) C_n^n0(t) C_b^n(t): the body at t in the body frame frozen at t = 0."""
    c0 = scipy_attitude(truth.geometry, truth.angles(np.zeros(1)))
    return c0.inv() * earth_turn(truth.earth, t) * scipy_attitude(truth.geometry, truth.angles(t))


def from_zero(device: dict | None) -> dict:
    """An emulated device's config block whose counter starts at 0 (unless it says otherwise): for tests of the
    frames themselves, which the emulator otherwise counts from a start drawn from the seed."""
    device = dict(device or {})
    device["timing"] = {"counter_start": 0, **device.get("timing", {})}
    return device


def interruptible() -> None:
    """``preexec_fn`` of a child stopped with SIGINT: the signal's default action, whatever the test process
    inherited (a worker that ignores SIGINT passes the ignoring on, and Python then installs no handler)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def processed(run_dir) -> dict:
    """A run directory's result.json without its ``record`` (who ran it, when: a replay has its own): what a replay
    of the recording reproduces bit for bit."""
    import json
    from pathlib import Path

    doc = json.loads((Path(run_dir) / "result.json").read_text())
    doc.pop("record", None)
    return doc
