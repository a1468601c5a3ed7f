"""A command's output directory (``--out``), claimed for the command's life: an exclusive ``fcntl.flock`` on
``OUT/.hil.lock`` keeps every other command out (the OS drops it when its holder ends, however it ends, so a
crashed command never blocks the next); a directory holding outputs the command would write is refused unless
``--overwrite``, which first removes them, so that no file of the replaced trial stays beside the new ones; and a
command refused at its start (an :class:`~hil.inputs.InputError`) leaves the directory as it found it."""

from __future__ import annotations

import fcntl
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
import time
from pathlib import Path
from typing import TYPE_CHECKING

from hil.inputs import InputError
from hil.outputs.figures import FIGURES

if TYPE_CHECKING:
    from hil.config import Config

LOCK_NAME = ".hil.lock"
NOISE_JSON = "noise.json"  # a noise characterisation's document (hil.outputs.noise)
# what a trial writes (docs/contracts.md, "Output files"), and a noise characterisation
TRIAL_OUTPUTS = ("result.json", "series.csv", "report.html", "junit.xml", "config.yaml", *FIGURES, "recording.mcap",
                 "recording.rrd", "fixture.rrd", "emulator.json", "emulator.log", "ports.json", "calibration.json",
                 "calibration.html", "calibration_residuals.png", "units")
NOISE_OUTPUTS = (NOISE_JSON, "allan.png", "report.html", "noise.rrd", "acquisition")
RECORDS = ("result.json", "recording.mcap", "noise.json")  # what another command could take for a trial's


def output_dir(out: str | Path | None, cfg: Config) -> Path:
    """``--out``, else ``output.dir``, else ``runs/NAME-TIME``."""
    if out:
        return Path(out)
    if cfg.output.dir:
        return Path(cfg.output.dir)
    return Path("runs") / f"{cfg.trial.name}-{time.strftime('%Y%m%d-%H%M%S')}"


class OutputDirError(InputError):
    """The output directory is another command's, or holds outputs and ``--overwrite`` was not given."""


@contextmanager
def claimed(out: Path, outputs: tuple[str, ...], overwrite: bool = False,
            inputs: tuple[Path, ...] = ()) -> Iterator[bool]:
    """``out`` (created if need be) for the ``with`` block, locked against every other command; refused when it
    holds any of ``outputs`` (the names the command writes) unless ``overwrite``, which removes them first but the
    command's ``inputs`` (a config given from there). Yields whether it removed any (another trial's outputs)."""
    fd, created = _lock(out)
    try:
        before = set(os.listdir(out))
        replaced = _clear(out, outputs, overwrite, {path.resolve() for path in inputs})
        try:
            yield replaced
        except InputError:
            _refused(out, set(os.listdir(out)) - before - {LOCK_NAME})
            raise
    finally:
        _unlock(out, fd, created)


def _lock(out: Path) -> tuple[int, bool]:
    """The open lock file of ``out`` holding its exclusive lock, and whether ``out`` was created for it."""
    path = out / LOCK_NAME
    while True:
        created = not out.exists()
        try:
            out.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except FileNotFoundError:  # its last holder removed the directory as we made it: make it again
            continue
        except OSError as exc:
            raise OutputDirError(f"--out {out}: cannot be written ({exc.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise OutputDirError(f"--out {out}: another hil command (pid {holder}) is writing its outputs there; "
                                 "wait for it to end or choose another directory") from None
        if _still_at(path, fd):
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            return fd, created
        os.close(fd)  # its holder removed it as it ended: lock the file now at the path


def _still_at(path: Path, fd: int) -> bool:
    """Whether the open file ``fd`` is the one at ``path`` (not one its last holder has since removed)."""
    try:
        return os.stat(path).st_ino == os.fstat(fd).st_ino
    except FileNotFoundError:
        return False


def _unlock(out: Path, fd: int, created: bool) -> None:
    """Remove the lock file while holding it (a command that opened it since finds it gone and tries again), then
    the directory if this command made it and left nothing in it."""
    try:
        os.unlink(out / LOCK_NAME)
    except FileNotFoundError:
        pass
    os.close(fd)
    if created:
        try:
            out.rmdir()
        except OSError:  # not empty: the command's outputs
            pass


def _clear(out: Path, outputs: tuple[str, ...], overwrite: bool, inputs: set[Path]) -> bool:
    """Refuse a directory holding any of ``outputs``, or with ``overwrite`` remove them (but ``inputs``); whether
    there were any."""
    found = [name for name in outputs if (out / name).exists() and (out / name).resolve() not in inputs]
    if found and not overwrite:
        raise OutputDirError(f"--out {out}: holds the outputs of a trial ({', '.join(found[:3])}"
                             f"{', ...' if len(found) > 3 else ''}); choose another directory, or --overwrite to "
                             "replace them")
    for name in found:
        _remove(out / name)
    return bool(found)


def _refused(out: Path, new: set[str]) -> None:
    """A command refused at its start: remove what it created (``new``), unless that holds a record another
    command could take (then it got further than its start, and what it recorded is kept)."""
    paths = [out / name for name in new]
    inside = [p for path in paths if path.is_dir() for p in path.rglob("*")]
    if not any(p.name in RECORDS for p in paths + inside):
        for path in paths:
            _remove(path)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
