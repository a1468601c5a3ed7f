"""Which pseudo-terminal a serial port's path leads to, so that a reopen never takes another program's.

A pty's number is handed to the next program that asks once the pty is gone. A reader reopening
``/dev/pts/N``, or a symbolic link still pointing there (a restarted emulator's name, a udev-style
name before its device returns), would then read that program's terminal in silence, and never
learn that the device came back elsewhere. So a path that leads to a pty may be opened when it is
the pty opened before (number and creation time), or when a link on the way has been replaced since
(a re-pointed link names the device anew, whatever number its new pty has). A path that leads to no
pty (a real port, whose node is recreated on replug; a network URL) is always opened.
"""

from __future__ import annotations

import os
import stat

MAX_LINKS = 40  # symbolic links followed from one path, as the kernel does

Identity = tuple[int, int]  # (device number, creation time) of a pty; (inode, change time) of a link


def links_of(path: str) -> tuple[Identity, ...]:
    """The identity of each symbolic link followed from ``path`` to what it names (a replaced link is a new one)."""
    found: list[Identity] = []
    while len(found) < MAX_LINKS:
        try:
            info = os.lstat(path)
            if not stat.S_ISLNK(info.st_mode):
                break
            target = os.readlink(path)
        except OSError:
            break
        found.append((info.st_ino, info.st_ctime_ns))
        path = os.path.join(os.path.dirname(path), target)
    return tuple(found)


def pty_at(path: str) -> Identity | None:
    """The identity of the pty ``path`` leads to; None when it leads to no pty, or to nothing."""
    try:
        if not os.path.realpath(path).startswith("/dev/pts/"):
            return None
        info = os.stat(path)
    except OSError:
        return None
    return info.st_rdev, info.st_ctime_ns


class PtyGuard:
    """Remembers the pty a path led to when last admitted, and the links that led there."""

    def __init__(self, path: str) -> None:
        self.path = path
        self._last: tuple[Identity, tuple[Identity, ...]] | None = None

    def admits(self) -> bool:
        """Whether the path may be opened now: not when the same links lead to another pty than the last one
        admitted. Creation times come from the kernel's coarse clock (a few ms)."""
        links = links_of(self.path)  # first: a link replaced meanwhile then only delays the open
        pty = pty_at(self.path)
        if pty is None:
            return True
        if self._last is not None and pty != self._last[0] and links == self._last[1]:
            return False
        self._last = (pty, links)
        return True
