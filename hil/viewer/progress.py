"""Console progress of a live trial (rich): time, live bias +- sigma, observability, stream health."""

from __future__ import annotations

import time

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from hil.estimation.online import Snapshot
from hil.units import UG


class ConsoleProgress:
    """A progress bar over the trial's duration with a status line; use as a context manager."""

    def __init__(self, duration: float | None, quiet: bool = False, console: Console | None = None) -> None:
        self.duration = duration
        self._progress = Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[time]}"),
                                  TimeElapsedColumn(), console=console or Console(stderr=True), transient=False,
                                  disable=quiet)
        self._task = self._progress.add_task("waiting for data", total=duration or 1.0, time="")
        self._last: tuple[float, dict[str, float]] | None = None

    def __enter__(self) -> ConsoleProgress:
        self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._progress.stop()

    def update(self, trial_time: float, snap: Snapshot | None, health: dict[str, dict[str, float]]) -> None:
        """Called by the trial about twice a second with the trial time (s), the latest snapshot and the
        stream health."""
        now = time.monotonic()
        frames = {name: health[name]["frames"] for name in ("imu", "table")}
        rates = {name: 0.0 for name in frames}
        if self._last is not None:
            then, before = self._last
            rates = {name: (frames[name] - before[name]) / max(now - then, 1e-9) for name in frames}
        self._last = (now, frames)
        if snap is None:
            text = "acquiring"
        elif snap.full.bias is None:
            text = f"rank {snap.full.observability.rank}/12: bias not observable yet"
        else:
            bias = " ".join(f"{b / UG:+.1f}+-{s / UG:.1f}" for b, s in zip(snap.full.bias, snap.full.bias_sigma))
            text = f"bias ug {bias} | rank {snap.full.observability.rank}"
        streams = " ".join(
            f"{name} {rates[name]:.0f}Hz c{health[name]['corrupt']:.0f} m{health[name]['missing']:.0f}"
            for name in ("imu", "table"))
        p99 = health["aligner"].get("age_p99_ms")
        latency = f" p99 {p99:.1f}ms" if p99 is not None else ""
        self._progress.update(self._task, completed=trial_time, description=f"{text} | {streams}{latency}",
                              time=f"{trial_time:.0f}/{self.duration or 0:.0f} s")
