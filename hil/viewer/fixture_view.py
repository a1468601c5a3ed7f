"""The fixture's overview of a trial of several units (docs/units.md, docs/viewer.md): one more Rerun recording
beside the units' own, named after the trial (the units' are ``<trial.name>.<unit>``), with every unit's bias
convergence side by side and, at the end, each unit's verdict and the fixture's table of units.

Per unit and axis ``/units/<name>/bias/<axis>/estimate``, ``sigma3_upper``, ``sigma3_lower`` and (emulated) ``truth``
in µg on ``trial_time``, the rows of :func:`hil.viewer.bias_view.bias_rows` of each unit's snapshots as its pipeline
publishes them; at the end ``/units/<name>/verdict`` (the markdown the unit's own ``/verdict`` ends with) and
``/fixture`` (a row per unit: name, serial, how it ended, verdict; logged at the start with every unit running).

Saved as ``OUT/fixture.rrd``; live (``spawn``, ``serve``) in the viewer the first unit's view started. Made before
the units' trials (each unit's pipeline listener from :meth:`FixtureView.listener`), opened once they are
(:meth:`FixtureView.open`). As :class:`~hil.viewer.trial_viewer.TrialViewer`, logging never blocks a unit's
thread: the snapshots are handed to one background thread, and dropped and counted when it falls behind.
"""

from __future__ import annotations

import threading
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from hil.estimation.online import Snapshot
from hil.pipeline.progress import Listener, Progress
from hil.viewer.bias_view import BiasTruth, bias_rows, log_bias_styles
from hil.viewer.blueprint import AXES, TIMELINE
from hil.viewer.chunks import Columns, Streams
from hil.viewer.judged_view import log_verdict
from hil.viewer.modes import ViewerOptions
from hil.viewer.log_jobs import LogJobs
from hil.viewer.trial_viewer import FILE_FLUSH_S, recording_stream

FIXTURE_RRD = "fixture.rrd"
FIXTURE_SERIES = ("estimate", "sigma3_upper", "sigma3_lower", "truth")  # of bias_view.SERIES; truth: emulated


@dataclass(frozen=True)
class _Unit:
    serial: str | None
    truth: BiasTruth | None


def unit_entity(name: str) -> str:
    """The entity of unit ``name`` in the overview: ``units/<name>``."""
    return f"units/{rr.escape_entity_path_part(name)}"


def fixture_markdown(name: str, rows: list[Mapping], ended: str | None = None, verdict: str | None = None) -> str:
    """``/fixture``: the trial's head (running, or how it ended and its verdict) and a row per unit of ``rows``
    (the index's ``units``: ``name``, ``dut_serial``, ``ended``, ``verdict``)."""
    head = f"## Fixture {name}: running" if ended is None else f"## Fixture {name}: {verdict} ({ended})"
    lines = [head, "", "| unit | serial | ended | verdict |", "|---|---|---|---|"]
    for row in rows:
        cells = [row["name"], row.get("dut_serial") or "—", row.get("ended") or "running", row.get("verdict") or "—"]
        lines.append("| " + " | ".join(str(cell).replace("|", "\\|") for cell in cells) + " |")
    return "\n".join(lines) + "\n"


def fixture_blueprint(units: list[str]) -> rrb.Blueprint:
    """A column per unit (its three bias axes over its verdict), the fixture's table under them; at 1600x1000 the
    verdicts' tables (a row per judged measurement, about ten) and the fixture's (three or four units) are whole."""
    columns = [rrb.Vertical(
        *(rrb.TimeSeriesView(origin=f"/{unit_entity(name)}/bias/{a}", name=f"{name}: bias {a} (µg)",
                             plot_legend=rrb.PlotLegend(visible=a == "x")) for a in AXES),
        rrb.TextDocumentView(origin=f"/{unit_entity(name)}/verdict", name=f"{name}: verdict"),
        row_shares=[4, 4, 4, 12], name=name) for name in units]  # fmt: skip
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(*columns), rrb.TextDocumentView(origin="/fixture", name="fixture: units, verdicts"),
                     row_shares=[11, 3]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
    )


class FixtureView:
    """The overview of the trial ``name`` writing to ``out`` as ``options`` ask (``none``: nothing); see the module
    docstring. ``blocking``: waits for room rather than drops (a benchmark's full cost)."""

    def __init__(self, options: ViewerOptions, out: Path, name: str, blocking: bool = False) -> None:
        self.options = options
        self.out = Path(out)
        self.name = name
        self.blocking = blocking
        self.rrd_path: Path | None = None
        self.dropped = 0  # snapshots not logged because the logging thread was behind
        self._units: dict[str, _Unit] = {}
        self._t_latest: dict[str, float] = {}
        self._lock = threading.Lock()
        self._rec: Streams | None = None
        self._file: rr.RecordingStream | None = None
        self._view: rr.RecordingStream | None = None
        self._columns: list[Columns] = []
        self._jobs: LogJobs | None = None  # the logging thread, once open
        self._closed = self._ended = False

    @property
    def error(self) -> BaseException | None:
        """The first error the logging thread met."""
        return self._jobs.error if self._jobs is not None else None

    def listener(self, unit: str, serial: str | None, truth: BiasTruth | None) -> Listener:
        """Unit ``unit`` (its ``serial``, an emulated unit's ``truth``) and its pipeline's listener: its snapshots
        to the overview once it is open."""
        self._units[unit] = _Unit(serial, truth)
        return lambda progress: self._progress(unit, progress)

    def open(self, units: list[str], connect: str | None) -> None:
        """Start the recording with the columns of ``units`` (the units that run); ``connect``: the gRPC URL of the
        viewer the first unit's view started (None: the .rrd alone)."""
        if self.options.mode == "none" or self._jobs is not None:
            return
        self._units = {name: self._units[name] for name in units}
        recording_id = uuid.uuid4()
        blueprint = fixture_blueprint(units)
        self.out.mkdir(parents=True, exist_ok=True)
        file = recording_stream(recording_id, FILE_FLUSH_S)
        file.save(self.out / FIXTURE_RRD, default_blueprint=blueprint)
        recs, columns = [file], [Columns(file, FILE_FLUSH_S)]
        if connect is not None:
            view = recording_stream(recording_id)
            view.set_sinks(rr.GrpcSink(connect), default_blueprint=blueprint)
            recs.append(view)
            columns.append(Columns(view, 0.0))
        rec = Streams(recs)
        for stream in recs:
            stream.send_recording_name(self.name)
        for unit, info in self._units.items():
            log_bias_styles(rec, info.truth is not None, prefix=f"{unit_entity(unit)}/", series=FIXTURE_SERIES)
        rows = [{"name": unit, "dut_serial": info.serial} for unit, info in self._units.items()]
        log_verdict(rec, 0.0, fixture_markdown(self.name, rows), "fixture")
        self.rrd_path, self._file, self._columns = self.out / FIXTURE_RRD, file, columns
        self._view = recs[1] if len(recs) > 1 else None
        self._jobs = LogJobs("rerun-fixture", "the fixture's overview", self._due, self._flush)
        self._rec = rec  # logging from here on

    def log_snapshots(self, unit: str, snaps: list[Snapshot]) -> None:
        """Unit ``unit``'s new snapshots; returns at once (dropped and counted when the logging thread is behind)."""
        if self._rec is None or self._closed or unit not in self._units or not snaps:
            return
        snaps = list(snaps)
        if not self._jobs.submit(lambda: self._write(unit, snaps), self.blocking):
            with self._lock:
                self.dropped += 1

    def unit_verdict(self, unit: str, markdown: str) -> None:
        """Unit ``unit``'s verdict and judged measurements (result.json's, the markdown its own ``/verdict`` ends
        with) to ``/units/<name>/verdict`` at its last trial time; closes the live logging first."""
        if self._rec is None or self._ended or unit not in self._units:
            return
        self.close()
        self._jobs.run(lambda: log_verdict(self._rec, self._t_latest.get(unit, 0.0), markdown,
                                      f"{unit_entity(unit)}/verdict"))

    def end(self, index: Mapping) -> None:
        """``/fixture`` from the trial's index result.json (its ``units``, ``ended`` and ``verdict``) at the last
        trial time, and the .rrd finished."""
        if self._rec is None or self._ended:
            return
        self.close()
        t = max(self._t_latest.values(), default=0.0)
        markdown = fixture_markdown(self.name, list(index["units"]), index["ended"], index["verdict"])
        self._jobs.run(lambda: log_verdict(self._rec, t, markdown, "fixture"))
        self._ended = True
        self._file.flush()
        self._file.disconnect()  # the .rrd is complete
        if self._view is not None:
            self._view.flush()
            self._view.disconnect()  # all is sent: a viewer that stops later finds nothing left to send

    def close(self) -> None:
        """Log what is queued and flush; the .rrd is finished by :meth:`end` (or the end of the process)."""
        if self._rec is None or self._closed:
            return
        self._closed = True
        self._jobs.stop()
        for rec in self._rec.recs:
            rec.flush()

    # -- the logging thread --

    def _progress(self, unit: str, progress: Progress) -> None:
        if progress.snapshots:
            self.log_snapshots(unit, progress.snapshots)

    def _due(self) -> None:
        """After each job: the rows due to each sink, at the latest unit's trial time."""
        t = max(self._t_latest.values(), default=0.0)
        for columns in self._columns:
            self._jobs.run(lambda c=columns: c.due(t))

    def _flush(self) -> None:
        """Once the queue is closed: every row held."""
        for columns in self._columns:
            self._jobs.run(columns.flush)

    def _write(self, unit: str, snaps: list[Snapshot]) -> None:
        for path, (t, values) in bias_rows(snaps, self._units[unit].truth).items():
            if path.rsplit("/", 1)[1] in FIXTURE_SERIES:
                for columns in self._columns:
                    columns.scalars(f"{unit_entity(unit)}/{path}", t, values)
        self._t_latest[unit] = max(self._t_latest.get(unit, 0.0), max(s.t for s in snaps))

