"""The console's status line: stream health first, as much as 80 columns hold, a plain line when not a terminal."""

from __future__ import annotations

import io

from rich.console import Console

from hil.viewer.console_progress import ConsoleProgress, fitted

HEALTH = {"imu": {"frames": 0, "corrupt": 3, "missing": 0}, "table": {"frames": 0, "corrupt": 0, "missing": 0},
          "aligner": {"age_p99_ms": 4.2}}


def test_the_parts_that_fit_are_kept_in_order_and_the_first_always():
    assert fitted(["a" * 10, "b" * 10, "c" * 5], 25) == "a" * 10 + " | " + "b" * 10
    assert fitted(["a" * 30, "b"], 20) == "a" * 20


def test_at_80_columns_the_health_and_the_time_come_first():
    progress = ConsoleProgress(600.0, console=Console(file=io.StringIO(), width=80))
    parts = progress.parts(12.0, None, HEALTH, {"imu": 200.0, "table": 200.0})
    assert parts[:2] == ["imu 200Hz c3 table 200Hz", "12/600 s"]
    line = fitted(parts, 80)
    assert len(line) <= 80 and line.startswith("imu 200Hz c3 table 200Hz | 12/600 s")


def test_without_a_terminal_plain_lines_are_printed_whole():
    out = io.StringIO()
    with ConsoleProgress(600.0, console=Console(file=out, width=80)) as progress:
        assert not progress.live
        progress.update(1.0, None, HEALTH)
        progress.update(1.5, None, HEALTH)  # within PLAIN_S: no second line
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imu 0Hz c3 table 0Hz | 1/600 s | acquiring")
