"""The trial's figures drawn by a child process that is started before the trial is computed.

Importing matplotlib costs about 0.4 s, more than drawing the three figures; a child that imports it at
once does so on the other core while the trial runs, and then only draws: each figure but the last in a
fork of itself, the last itself, on both cores. The job goes over the child's
standard input: one line of JSON (output directory, result, the series' shape), then the series as
little-endian float64 bytes. Whatever goes wrong with the child, the figures are drawn in this process
instead (one line on stderr says why): they are never lost.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np

from hil import child_env, end_child
from hil.outputs.figures import FIGURES, pyplot, write_figures

WAIT_S = 120.0  # drawing takes well under a second; a child that takes this long is stuck
DONE = b"drawn\n"  # what the child answers on its standard output
# The child runs this much nicer than the trial: its import then takes the time the trial's own processes
# leave idle instead of slowing them (hil simulate of the paper scenario 1.57 -> 1.52 s, paired), and by the
# time it draws nothing else runs. Its forks inherit it.
NICENESS = 10


class FigureProcess:
    """A child process ready to draw one trial's figures (:func:`hil.outputs.figures.write_figures`).

    Use as a context manager; :meth:`draw` has the signature of ``write_figures``. A child not given a
    job is ended on :meth:`close`.
    """

    def __init__(self) -> None:
        env = child_env(OPENBLAS_NUM_THREADS="1")  # drawing needs no BLAS threads, and the child forks
        self._child: subprocess.Popen | None = subprocess.Popen(
            [sys.executable, "-m", __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, env=env)  # fmt: skip

    def __enter__(self) -> FigureProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def draw(self, out: Path, series: np.ndarray, result: dict) -> None:
        """Draw the figures of ``series`` into ``out`` in the child; in this process if the child fails."""
        child, self._child = self._child, None
        reason = "used once already"
        if child is not None:
            reason = _hand_over(child, out, series, result)
        if reason:
            print(f"hil: the figure process failed ({reason}); drawing the figures here", file=sys.stderr)
            write_figures(out, series, result)

    def close(self) -> None:
        """End a child that was given no job, at once (it has only imported)."""
        child, self._child = self._child, None
        if child is not None:
            end_child(child, (child.stdin, child.stdout, child.stderr))


def _hand_over(child: subprocess.Popen, out: Path, series: np.ndarray, result: dict) -> str:
    """Give ``child`` the job and wait for it; '' when it drew the figures, else why not."""
    data = np.ascontiguousarray(series, dtype="<f8")
    header = json.dumps({"out": str(Path(out).resolve()), "shape": data.shape, "result": result})
    try:
        answer, err = child.communicate(header.encode() + b"\n" + data.tobytes(), timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        child.kill()
        child.communicate()
        return f"no answer within {WAIT_S:.0f} s"
    except OSError as exc:  # the child is gone: its input pipe is closed
        child.kill()
        child.wait()
        return str(exc)
    if child.returncode != 0 or answer != DONE:
        lines = err.decode(errors="replace").strip().splitlines()
        return lines[-1] if lines else f"exit code {child.returncode}"
    return ""


def _serve() -> None:
    """The child: import matplotlib, then draw the job read from standard input (none: exit)."""
    if hasattr(os, "nice"):
        os.nice(NICENESS)
    pyplot()  # imported now, while the parent computes the trial
    line = sys.stdin.buffer.readline()
    if not line:
        return
    job = json.loads(line)
    shape = tuple(job["shape"])
    data = sys.stdin.buffer.read(8 * int(np.prod(shape)))
    _draw_apart(Path(job["out"]), np.frombuffer(data, dtype="<f8").reshape(shape), job["result"])
    sys.stdout.buffer.write(DONE)
    sys.stdout.flush()
    os._exit(0)  # the figures are written and closed: no interpreter teardown (0.1-0.2 s) for the parent to wait for


def _draw_apart(out: Path, series: np.ndarray, result: dict) -> None:
    """Each figure but the last drawn by a fork of this process (matplotlib already imported), the last
    here: the trial is computed by then and both cores are free. Raises if any part fails."""
    if not hasattr(os, "fork"):
        write_figures(out, series, result)
        return
    forks = {}
    try:
        for name in FIGURES[:-1]:
            pid = os.fork()
            if pid == 0:
                _draw_and_exit(out, series, result, name)
            forks[pid] = name
        write_figures(out, series, result, FIGURES[-1:])
    finally:
        failed = [name for pid, name in forks.items() if os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) != 0]
    if failed:
        raise RuntimeError(f"drawing {', '.join(failed)} failed")


def _draw_and_exit(out: Path, series: np.ndarray, result: dict, name: str) -> None:
    """A fork's work: draw one figure, exit 0 if it is written, 1 with the traceback on stderr if not."""
    code = 0
    try:
        write_figures(out, series, result, (name,))
    except BaseException:  # noqa: BLE001 - told by the exit code, the traceback on stderr
        traceback.print_exc()
        code = 1
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    _serve()
