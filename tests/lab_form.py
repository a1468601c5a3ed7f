"""The lab form of a trial for tests: ``hil emulate`` in its own process, streaming from the start as powered
hardware does, and the harness pointed at its ports, started whenever the test says."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
import time
from pathlib import Path

import yaml

from emulators.process import wait_for_ports

SWING = {"outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
         "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
         "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6}}
BIAS_UG = [60.0, 150.0, 260.0]


def emulated(rate_hz: float = 200.0, protocol: str = "kvh1750", duration_s: float = 60.0, seed: int = 11,
             kind: str = "swing", **imu: object) -> dict:
    """An emulated swing (or static) trial's config as a mapping; ``imu`` keys go into its ``imu`` block."""
    return {"trial": {"name": "lab-form", "duration_s": duration_s, "rate_hz": 200.0, "seed": seed},
            "site": {"latitude_deg": 32.0, "longitude_deg": 118.0, "height_m": 10.0},
            "turntable": {"latch_delay_us": 50, "motion": {"kind": kind, "axes": SWING}},
            "imu": {"protocol": protocol, "rate_hz": rate_hz,
                    "errors": {"accel_bias_ug": BIAS_UG, "accel_noise_ug": [50] * 3,
                               "gyro_bias_dph": [0.01] * 3, "gyro_noise_dph": [0.01] * 3}, **imu},
            "estimator": {"solve_rate_hz": 1}}


class Emulator:
    """``python -m emulators CONFIG --ports-file P`` (what ``hil emulate`` runs), streaming from the start."""

    def __init__(self, tmp: Path, cfg: dict, *args: str, name: str = "emulate", duration: float | None = None) -> None:
        self.config = tmp / f"{name}.yaml"
        self.config.write_text(yaml.safe_dump(cfg))
        self.ports_file = tmp / f"{name}-ports.json"
        self.stats_file = tmp / f"{name}-stats.json"
        self.proc = subprocess.Popen([sys.executable, "-m", "emulators", str(self.config), "--ports-file",
                                      str(self.ports_file), "--speed", "1", "--stats-file", str(self.stats_file),
                                      *(["--duration", str(duration)] if duration else []), *args],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        self.ports = wait_for_ports(self.ports_file, lambda: self.proc.poll() is None, 20.0)
        assert self.ports is not None, self.proc.stderr.read().decode()
        self.started = time.monotonic()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(10)

    def __enter__(self) -> Emulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def lab_config(cfg: dict, ports: dict, tmp: Path, name: str = "lab", commanded: bool = False, **output: object) -> Path:
    """The same trial in the lab form: serial (or CAN) ports of the running emulator, no emulated truth; with
    ``commanded`` the harness drives the table over its command port."""
    lab = copy.deepcopy(cfg)
    lab["turntable"].update(source="serial", data_port=ports["turntable_data"])
    lab["turntable"].pop("command_port", None)
    if commanded:
        lab["turntable"]["command_port"] = ports["turntable_cmd"]
    imu = lab["imu"]
    imu.pop("errors", None)
    imu.pop("timing", None)
    imu.pop("faults", None)
    lab["turntable"].pop("faults", None)
    lab["turntable"].pop("timing", None)
    if isinstance(ports["imu"], dict):
        imu.update(source="can", can={"interface": ports["imu"]["interface"], "channel": ports["imu"]["channel"]})
    else:
        imu.update(source="serial", port=ports["imu"])
    lab["output"] = {"limits": {}, **output}
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(lab))
    return path


def result(out: Path) -> dict:
    return json.loads((out / "result.json").read_text())


def within_sigmas(result_doc: dict, sigmas: float = 5.0) -> bool:
    """The estimated accelerometer bias within ``sigmas`` of its 1-sigma of the emulator's truth, every axis."""
    estimate = result_doc["estimate"]
    return all(abs(b - t) <= sigmas * s for b, t, s in zip(estimate["accel_bias_ug"], BIAS_UG,
                                                          estimate["accel_bias_sigma_ug"], strict=True))
