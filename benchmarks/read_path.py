"""The path of one live read through the harness, traced: which of the project's modules the read's bytes pass
on the processing thread, in the order they are first entered, until the estimator takes the samples, and the
call stack at that moment.

The read is an IMU read of one block (and the table's read before it) of the default emulated trial, fed as the
live trial feeds it (``TrialProcessor.feed``) once the two streams are paired. Before the queue, on the reader's
thread, a read passes drivers/transport.py (the port), drivers/reader.py (the reader) and hil/trial/live.py
(``Fanout``: the recorder and the queue); those are named, not traced.

    .venv/bin/python benchmarks/read_path.py
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from drivers.codec import RawChunk  # noqa: E402
from drivers.controllers import data_codec  # noqa: E402
from drivers.registry import imu_codec  # noqa: E402
from emulators.simulation import Simulation  # noqa: E402
from hil.config import load_config  # noqa: E402
from hil.pipeline.processor import TrialProcessor  # noqa: E402
from hil.pipeline.settings import PipelineSettings
from hil.samples import ImuSample, TableSample  # noqa: E402

OURS = ("hil", "drivers", "emulators")
ESTIMATOR = ("hil.estimation.online", "update_many")


def _module(frame) -> str | None:
    name = frame.f_globals.get("__name__", "")
    return name if name.split(".")[0] in OURS else None


def main() -> None:
    cfg = load_config(ROOT / "configs" / "emulated_swing.yaml")
    batch = next(Simulation.from_config(cfg).batches(chunk=10**6))
    imu_c, table_c = imu_codec(cfg.imu, cfg.imu_rate_hz), data_codec(cfg.turntable, cfg.table_counts_per_frame)
    block = cfg.block_samples
    processor = TrialProcessor(PipelineSettings.of(cfg), None, 1.0)

    def reads(start: int) -> tuple[RawChunk, RawChunk]:
        at = (start + block) / cfg.imu_rate_hz
        imu = b"".join(imu_c.encode(imu_c.from_sample(ImuSample(k + 1, tuple(batch.dtheta[k]), tuple(batch.dv[k]))))
                       for k in range(start, start + block))
        table = b"".join(table_c.encode(table_c.from_sample(TableSample(k + 1, tuple(batch.angles[k]))))
                         for k in range(start, start + block))
        return RawChunk("table", at, table), RawChunk("imu", at, imu)

    start = 0
    for start in range(0, round(10 * cfg.imu_rate_hz), block):  # 10 s: the streams are paired by then
        for chunk in reads(start):
            processor.feed(chunk)
    table, imu = reads(start + block)
    processor.feed(table)

    entered: list[str] = []
    stack: list[str] = []

    def profile(frame, event, _arg):
        module = _module(frame)
        if event != "call" or module is None:
            return
        if module not in entered:
            entered.append(module)
        if (module, frame.f_code.co_name) == ESTIMATOR and not stack:
            f = frame
            while f is not None:
                if _module(f) is not None:
                    stack.append(f"{_module(f)}.{f.f_code.co_name}")
                f = f.f_back

    sys.setprofile(profile)
    processor.feed(imu)
    sys.setprofile(None)
    if not stack:
        raise SystemExit("the read was not taken by the estimator: no path to show")
    before = entered[: entered.index(ESTIMATOR[0])]
    print(f"one IMU read of {block} samples ({cfg.imu.protocol}, {cfg.imu_rate_hz:g} Hz), paired streams")
    print("before the queue (reader thread): drivers.transport, drivers.reader, hil.trial.live (Fanout)")
    print(f"processing thread: {len(before)} modules entered before the estimator, in order:")
    print("  " + " -> ".join(before))
    print(f"call stack at the estimator ({len(stack)} frames of the project, innermost first):")
    for line in stack:
        print("  " + line)
    processor_frames = sum(line.startswith("hil.pipeline.processor.") for line in stack)
    print(f"frames of hil.pipeline.processor on that stack: {processor_frames}")


if __name__ == "__main__":
    main()
