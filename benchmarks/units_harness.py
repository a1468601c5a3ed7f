"""Several units on one table at real time, in the lab form: CPU share and memory of the harness process.

``hil emulate`` of N KVH 1750 units (mounted apart, each its own errors and counter start) streams from its start as
powered hardware does; ``hil run`` of the same units in the lab form (each unit's serial port, the table's) attaches
``--late`` s later, in its own process. Printed: the harness's CPU (user + system, all threads) over its wall time as
a share of one core, its maximum resident memory, and per unit how its trial ended, its samples lost / corrupt /
unpaired, how it was paired and its bias against the truth.

    .venv/bin/python benchmarks/units_harness.py [--units 4] [--rate 1000] [--duration 600] [--late 3]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from emulators.process import stop_emulator, wait_for_ports

SWING = {"outer": {"amplitude_deg": 8, "period_s": 8, "center_deg": 5},
         "middle": {"amplitude_deg": 6, "period_s": 10, "center_deg": 2},
         "inner": {"amplitude_deg": 13, "period_s": 8, "center_deg": 6}}


def units_config(n: int, rate: float, duration: float) -> dict:
    """N emulated KVH 1750 units at ``rate`` Hz, each mounted a quarter turn of yaw from the last."""
    units = [{"name": f"kvh-{k}", "record": {"dut_serial": f"KVH-{k:04d}"}, "mounting_deg": [90 * k % 360, 0, 0],
              "imu": {"protocol": "kvh1750", "rate_hz": rate, "baudrate": 921600,
                      "errors": {"accel_bias_ug": [60 + 10 * k, 150 - 20 * k, 260 + 5 * k], "accel_noise_ug": [50] * 3,
                                 "gyro_bias_dph": [0.01] * 3, "gyro_noise_dph": [0.01] * 3}}} for k in range(n)]
    return {"trial": {"name": "units-bench", "duration_s": duration, "rate_hz": 200.0, "seed": 3},
            "site": {"latitude_deg": 32.0, "longitude_deg": 118.0, "height_m": 10.0},
            "turntable": {"latch_delay_us": 50, "motion": {"kind": "swing", "axes": SWING}},
            "units": units, "estimator": {"solve_rate_hz": 1}, "output": {"limits": {}}}


def lab_form(cfg: dict, ports: dict) -> dict:
    """The units config reading the running emulator's ports, without the emulated truth."""
    lab = json.loads(json.dumps(cfg))
    lab["turntable"].update(source="serial", data_port=ports["turntable_data"])
    for unit in lab["units"]:
        imu = unit["imu"]
        unit["imu"] = {"protocol": imu["protocol"], "rate_hz": imu["rate_hz"], "baudrate": imu["baudrate"],
                       "source": "serial", "port": ports["units"][unit["name"]]["imu"]}
    return lab


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--units", type=int, default=4)
    parser.add_argument("--rate", type=float, default=1000.0, help="each unit's imu.rate_hz")
    parser.add_argument("--duration", type=float, default=600.0, help="s of the harness's trial")
    parser.add_argument("--late", type=float, default=3.0, help="s from the emulator's start to the harness's")
    args = parser.parse_args()
    cfg = units_config(args.units, args.rate, args.duration + args.late + 10.0)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        (out / "units.yaml").write_text(yaml.safe_dump(cfg))
        emulator = subprocess.Popen([sys.executable, "-m", "emulators", str(out / "units.yaml"), "--ports-file",
                                     str(out / "ports.json"), "--speed", "1"], stdout=subprocess.DEVNULL)
        try:
            ports = wait_for_ports(out / "ports.json", lambda: emulator.poll() is None, 30.0)
            (out / "lab.yaml").write_text(yaml.safe_dump(lab_form(cfg, ports)))
            time.sleep(args.late)
            wall0 = time.monotonic()
            harness = subprocess.run([sys.executable, "-m", "hil.cli", "run", str(out / "lab.yaml"), "--duration",
                                      str(args.duration), "--out", str(out / "run"), "--viewer", "none", "--quiet",
                                      "--no-figures", "--no-history"], check=False)
            wall = time.monotonic() - wall0
            usage = resource.getrusage(resource.RUSAGE_CHILDREN)  # the harness's alone: the emulator is not reaped
        finally:
            stop_emulator(emulator)
        cpu = usage.ru_utime + usage.ru_stime
        print(f"{args.units} units, KVH 1750 at {args.rate:g} Hz, {args.duration:g} s, attached {args.late:g} s late; "
              "load average (1, 5, 15 min) before " + " ".join(f"{x:.2f}" for x in load_before) + ", after "
              + " ".join(f"{x:.2f}" for x in os.getloadavg()))
        print(f"harness exit {harness.returncode}, {wall:.1f} s wall, CPU {cpu:.1f} s = {100 * cpu / wall:.1f} % of "
              f"one core (all threads), max resident memory {usage.ru_maxrss / 1024:.0f} MiB")
        for name in (unit["name"] for unit in cfg["units"]):
            doc = json.loads((out / "run" / "units" / name / "result.json").read_text())
            s = doc["streams"]
            estimate = doc["estimate"]
            bias = ", ".join(f"{b:.1f}+-{e:.2f}" for b, e in zip(estimate["accel_bias_ug"] or (),
                                                                estimate["accel_bias_sigma_ug"] or ()))
            print(f"  {name}: {doc['ended']}; {s['aligned']} aligned, {s['dropped']} lost, {s['corrupt']} corrupt, "
                  f"{s['imu_unpaired']} unpaired; paired by {s['sync']['paired_by']}; bias ug {bias}")


if __name__ == "__main__":
    main()
