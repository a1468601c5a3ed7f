"""How a trial's recording streams are sent their data: the time series and gimbal poses held per entity and
sent as one chunk each (``send_columns``) every so many seconds of trial time, and the rest (static data, the
cone, the calibration's markers) logged as it comes to every stream.

Every chunk in a .rrd carries its own schema (about 1 kB); a chunk per entity per call made a 60 s trial's
file 4 MB of mostly schemas. Held for ``period_s`` of trial time, the file gets a chunk per entity that often
whatever the pace of the trial (real time or ``--speed max``); a live view's stream is sent every call's rows
at once (``period_s`` 0).
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from hil.viewer.blueprint import TIMELINE


class Streams:
    """Several recording streams of one recording as one: ``log`` and ``set_time`` go to each."""

    def __init__(self, recs: list[rr.RecordingStream]) -> None:
        self.recs = list(recs)

    def log(self, *args, **kwargs) -> None:
        for rec in self.recs:
            rec.log(*args, **kwargs)

    def set_time(self, *args, **kwargs) -> None:
        for rec in self.recs:
            rec.set_time(*args, **kwargs)


class Columns:
    """Rows of time series (``Scalars``) and gimbal poses (``Transform3D`` quaternions) held per entity, sent to
    ``rec`` as one chunk per entity once the trial time reaches the next multiple of ``period_s`` (0: at every
    :meth:`due`), and by :meth:`flush`."""

    def __init__(self, rec: rr.RecordingStream, period_s: float) -> None:
        self.rec = rec
        self.period_s = period_s
        self._rows: dict[str, tuple[str, list[np.ndarray], list[np.ndarray]]] = {}
        self._next_flush_t = period_s

    def scalars(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        """Rows (N, K) at trial times t (N,) s; K may grow from one call to the next (a new series)."""
        self._hold(path, "scalars", t, values)

    def quaternions(self, path: str, t: np.ndarray, q: np.ndarray) -> None:
        """Rotations (N, 4) (x, y, z, w) at trial times t (N,) s."""
        self._hold(path, "quaternion", t, q)

    def due(self, t: float) -> None:
        """Send what is held when trial time ``t`` s has reached the next flush."""
        if self._rows and t >= self._next_flush_t:
            self.flush()
            if self.period_s > 0:
                self._next_flush_t = (np.floor(t / self.period_s) + 1.0) * self.period_s

    def flush(self) -> None:
        """Send every entity's rows held, one chunk each."""
        rows, self._rows = self._rows, {}
        for path, (kind, times, values) in rows.items():
            if kind == "quaternion":
                columns = rr.Transform3D.columns(quaternion=np.vstack(values))
            else:
                flat = np.concatenate([v.ravel() for v in values])
                columns = rr.Scalars.columns(scalars=flat).partition([v.shape[1] for v in values for _ in v])
            self.rec.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=np.concatenate(times))],
                                  columns=columns)  # fmt: skip

    def _hold(self, path: str, kind: str, t: np.ndarray, values: np.ndarray) -> None:
        _, times, rows = self._rows.setdefault(path, (kind, [], []))
        times.append(np.asarray(t, dtype=float))
        rows.append(np.asarray(values, dtype=float).reshape(len(t), -1))
