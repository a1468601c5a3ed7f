"""A simulation's batches (:meth:`emulators.simulation.Simulation.batches`) computed by a child process.

On a thread the emulator barely overlaps the estimator (the GIL); a child started with ``hil simulate``
imports the emulator (about 0.25 s) while this process imports the estimator, then
computes the batches on the other core, about two ahead of the estimator (what its output pipe holds). The
config goes over the child's standard input as JSON (``Config.model_dump_json``); each batch comes back on
its standard output as a header (sample count, t0, whether angles follow), then its arrays as little-endian
float64 bytes; a header of count zero follows the last. An error in the child is raised in the consumer
with the child's message; a consumer that stops early ends the child.
"""

from __future__ import annotations

import fcntl
import os
import struct
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from typing import TYPE_CHECKING, BinaryIO

from hil import child_env, end_child

if TYPE_CHECKING:  # imported by the child: this process starts it before it imports numpy and pydantic
    import numpy as np

    from hil.config import Config
    from hil.samples import AlignedBatch

HEADER = struct.Struct("<qd??")  # samples (0: no more batches), t0 (s), angles present, temperatures present
AHEAD = 2  # batches the output pipe holds
INPUT_ERROR = 2  # the child's exit code for bad input (hil.config.InputError), as the command line's


class SimulationProcess:
    """A child process that imports the emulator at once, then computes the batches of one config.

    Use as a context manager; :meth:`batches` hands the child its config (or :meth:`start` earlier, so that the
    child computes its first batches while this process goes on). A child not given one, or whose batches are
    not all read, is ended on :meth:`close`.
    """

    def __init__(self) -> None:
        self._err = tempfile.TemporaryFile()  # the child's stderr: read when it fails
        self._child: subprocess.Popen | None = subprocess.Popen(
            [sys.executable, "-m", __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err,
            env=child_env())  # fmt: skip

    def __enter__(self) -> SimulationProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def batches(self, cfg: Config) -> Iterator[AlignedBatch]:
        """Hand ``cfg`` to the child now (unless :meth:`start` has); its batches as they come, those of
        ``Simulation.from_config(cfg)``. Raises the child's :class:`~hil.config.InputError` as one, any other
        error as a RuntimeError."""
        self.start(cfg)
        return self._read(self._child)

    def start(self, cfg: Config) -> None:
        """Hand ``cfg`` to the child now, once: it computes its first batches (as many as the pipe holds) before
        :meth:`batches` reads them."""
        child = self._child
        if child.stdin.closed:
            return
        try:
            child.stdin.write(cfg.model_dump_json().encode())
            child.stdin.close()
        except BrokenPipeError:  # the child is gone: reading its output says why
            pass

    def close(self) -> None:
        """End the child at once (if it has not exited) and close its pipes."""
        child, self._child = self._child, None
        if child is not None:
            end_child(child, (child.stdin, child.stdout, self._err))

    def _read(self, child: subprocess.Popen) -> Iterator[AlignedBatch]:
        try:
            while (batch := _read_batch(child.stdout)) is not None:
                yield batch
        except EOFError:
            raise self._failure(child) from None
        finally:
            self.close()

    def _failure(self, child: subprocess.Popen) -> Exception:
        """The error of a child that ended its output early, with its last line on stderr."""
        child.wait()
        self._err.seek(0)
        lines = self._err.read().decode(errors="replace").strip().splitlines()
        reason = lines[-1] if lines else f"exit code {child.returncode}"
        if child.returncode == INPUT_ERROR:
            from hil.config import InputError

            return InputError(reason)
        return RuntimeError(f"the simulation process failed: {reason}")


def _read_batch(stream: BinaryIO) -> AlignedBatch | None:
    """The next batch on ``stream``, None after the last; EOFError if the stream ends before."""
    import numpy as np  # here, not with the module: the child is started first

    from hil.samples import AlignedBatch

    n, t0, angles, temperatures = HEADER.unpack(_filled(stream, bytearray(HEADER.size)))
    if n == 0:
        return None
    t, dtheta, dv = (_filled(stream, np.empty(shape, "<f8")) for shape in ((n,), (n, 3), (n, 3)))
    angles = _filled(stream, np.empty((n, 3), "<f8")) if angles else None
    temperature = _filled(stream, np.empty(n, "<f8")) if temperatures else None
    return AlignedBatch(t, dtheta, dv, angles, t0, temperature_c=temperature)


def _filled(stream: BinaryIO, buffer: bytearray | np.ndarray) -> bytearray | np.ndarray:
    """``buffer`` filled from ``stream``; EOFError if the stream ends first."""
    if stream.readinto(buffer) != memoryview(buffer).nbytes:
        raise EOFError
    return buffer


def _write_batch(out: BinaryIO, batch: AlignedBatch) -> None:
    import numpy as np

    out.write(HEADER.pack(len(batch), batch.t0, batch.angles is not None, batch.temperature_c is not None))
    for array in (batch.t, batch.dtheta, batch.dv, batch.angles, batch.temperature_c):
        if array is not None:
            out.write(np.ascontiguousarray(array, dtype="<f8"))


def _serve() -> None:
    """The child: import the emulator, then write the batches of the config read from standard input."""
    out = os.fdopen(os.dup(1), "wb")  # the batches' pipe; standard output becomes stderr: nothing else goes in
    os.dup2(2, 1)
    from emulators.simulation import CHUNK, Simulation
    from hil.config import Config, InputError

    try:
        fcntl.fcntl(out.fileno(), fcntl.F_SETPIPE_SZ, AHEAD * CHUNK * 10 * 8)  # 10 float64 a sample
    except (AttributeError, OSError):  # not Linux, or more than the system allows: the default size
        pass
    try:
        for batch in Simulation.from_config(Config.model_validate_json(sys.stdin.buffer.read())).batches():
            _write_batch(out, batch)
    except Exception as exc:  # noqa: BLE001 - told to the parent in one line, the last on stderr
        text = " ".join(str(exc).split())
        print(text if isinstance(exc, InputError) else f"{type(exc).__name__}: {text}", file=sys.stderr, flush=True)
        os._exit(INPUT_ERROR if isinstance(exc, InputError) else 1)
    out.write(HEADER.pack(0, 0.0, False, False))
    out.flush()
    os._exit(0)  # the batches are flushed: no interpreter teardown for the parent to wait for


if __name__ == "__main__":
    _serve()
