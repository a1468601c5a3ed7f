"""Console progress of a live trial (rich): stream health first, then the time, the live bias +- sigma and
observability, the freshness of the estimate, as many of them as the terminal's width holds. When stderr is not
a terminal (a log file, CI) a plain line is printed every ``PLAIN_S`` instead of a live display."""

from __future__ import annotations

import threading
import time

from rich.console import Console
from rich.progress import Progress, TextColumn

from hil.estimation.online import Snapshot
from hil.units import UG
from hil.vocabulary import Stream

PLAIN_S = 5.0  # s between the plain lines when stderr is not a terminal
SEPARATOR = " | "


def fitted(parts: list[str], width: int) -> str:
    """The parts, in order, joined by ``SEPARATOR``: as many of the first as fit in ``width`` (the first one
    always, cut to the width)."""
    line = parts[0][:width]
    for part in parts[1:]:
        if len(line) + len(SEPARATOR) + len(part) > width:
            break
        line += SEPARATOR + part
    return line


class ConsoleProgress:
    """The trial's status line on stderr; use as a context manager."""

    def __init__(self, duration: float | None, quiet: bool = False, console: Console | None = None) -> None:
        self.duration = duration
        self.console = console or Console(stderr=True)
        self.quiet = quiet
        self.live = self.console.is_terminal and not quiet
        self._progress = Progress(TextColumn("{task.description}"), console=self.console, transient=False,
                                  disable=not self.live)
        self._task = self._progress.add_task("waiting for data", total=duration or 1.0)
        self._last: tuple[float, dict[str, float]] | None = None
        self._next_plain = 0.0

    def __enter__(self) -> ConsoleProgress:
        self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._progress.stop()

    def update(self, trial_time: float, snap: Snapshot | None, health: dict[str, dict[str, float]]) -> None:
        """Called by the trial about twice a second with the trial time (s), the latest snapshot and the
        stream health."""
        now = time.monotonic()
        frames = {name: health[name]["frames"] for name in Stream}
        rates = {name: 0.0 for name in frames}
        if self._last is not None:
            then, before = self._last
            rates = {name: (frames[name] - before[name]) / max(now - then, 1e-9) for name in frames}
        self._last = (now, frames)
        self.show(trial_time, self.parts(trial_time, snap, health, rates))

    def show(self, trial_time: float, parts: list[str]) -> None:
        """The status line of ``parts`` at ``trial_time`` (s): live on a terminal (as many parts as fit), else a
        plain line of every part every ``PLAIN_S``."""
        now = time.monotonic()
        line = fitted(parts, self.console.width) if self.live else SEPARATOR.join(parts)
        if self.live:
            self._progress.update(self._task, completed=trial_time, description=line)
        elif not self.quiet and now >= self._next_plain:
            self._next_plain = now + PLAIN_S
            self.console.print(line, soft_wrap=True, highlight=False, markup=False)

    def warn(self, text: str) -> None:
        """A warning line above the status line (printed when quiet too)."""
        self.console.print(f"hil: WARNING: {text}", soft_wrap=True, highlight=False, markup=False)

    def parts(self, trial_time: float, snap: Snapshot | None, health: dict[str, dict[str, float]],
              rates: dict[str, float]) -> list[str]:
        """The status line's parts, most important first."""
        streams = []
        for name in Stream:
            faults = "".join(f" {key[0]}{health[name][key]:.0f}" for key in ("corrupt", "missing") if health[name][key])
            streams.append(f"{name} {rates[name]:.0f}Hz{faults}")
        p99 = health["aligner"].get("age_p99_ms")
        return [" ".join(streams), f"{trial_time:.0f}/{self.duration or 0:.0f} s", estimate_text(snap),
                *([f"age p99 {p99:.1f} ms"] if p99 is not None else [])]


def estimate_text(snap: Snapshot | None, compact: bool = False) -> str:
    """The live estimate in a few words: the bias +- sigma (ug) and the observability's rank (``compact``: the
    bias alone, to whole ug)."""
    if snap is None:
        return "acquiring"
    if snap.full.bias is None:
        return f"rank {snap.full.observability.rank}/12" + ("" if compact else ": bias not observable yet")
    digits = 0 if compact else 1
    bias = " ".join(f"{b / UG:+.{digits}f}+-{s / UG:.1f}" for b, s in zip(snap.full.bias, snap.full.bias_sigma))
    return bias if compact else f"bias ug {bias} rank {snap.full.observability.rank}"


class UnitsProgress:
    """One status line for the units of a trial (docs/units.md): the trial time, then each unit's name and live
    bias (ug). Each unit's trial calls :meth:`updater`'s function from its own thread."""

    def __init__(self, progress: ConsoleProgress, names: list[str]) -> None:
        self.progress = progress
        self._estimates = dict.fromkeys(names, "acquiring")
        self._times = dict.fromkeys(names, 0.0)
        self._lock = threading.Lock()

    def updater(self, name: str):
        """The progress hook of the unit ``name`` (:attr:`hil.trial.live.TrialHooks.on_progress`)."""

        def update(trial_time: float, snap: Snapshot | None, health: dict) -> None:
            with self._lock:
                self._times[name], self._estimates[name] = trial_time, estimate_text(snap, compact=True)
                latest = max(self._times.values())
                units = [f"{unit} {text}" for unit, text in self._estimates.items()]
                self.progress.show(latest, [f"{latest:.0f}/{self.progress.duration or 0:.0f} s", *units])

        return update
