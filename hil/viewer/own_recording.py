"""A view with a recording of its own, not a trial's (a noise characterisation's, a plan's): written to its .rrd
in every mode and, for ``spawn`` and ``serve``, sent to a viewer started for it (:mod:`hil.viewer.rerun_process`)."""

from __future__ import annotations

import subprocess
import uuid
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from hil.viewer.rerun_process import start_viewer, stop_served, telemetry_requested
from hil.viewer.trial_viewer import APPLICATION_ID


class OwnRecording:
    """The recording ``name`` in ``mode`` (``spawn``, ``serve`` or ``save``) to ``rrd_path``, laid out by
    ``blueprint``; ``close``, ``stop``, ``mode``, ``url`` and ``viewer_process`` as a trial's viewer has them
    (:func:`hil.trial.viewer_feed.finish_viewer`), ``grpc_url`` the started viewer's (None in ``save`` mode)."""

    def __init__(self, mode: str, rrd_path: Path, blueprint: rrb.Blueprint, name: str, bind: str = "127.0.0.1"
                 ) -> None:
        self.mode = mode
        self.url: str | None = None
        self.grpc_url: str | None = None
        self.viewer_process: subprocess.Popen | None = None
        self.rrd_path = Path(rrd_path)
        self.rrd_path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        rr.set_log_time_enabled(False, recording=self.rec)
        rr.set_log_tick_enabled(False, recording=self.rec)
        sinks = [rr.FileSink(str(self.rrd_path))]
        if mode in ("spawn", "serve"):
            self.viewer_process, self.grpc_url, self.url = start_viewer(mode, bind, telemetry_requested())
            sinks.append(rr.GrpcSink(self.grpc_url))
        self.rec.set_sinks(*sinks, default_blueprint=blueprint)
        self.rec.send_recording_name(name)
        self._closed = False

    def close(self) -> None:
        """Flush and finish the .rrd; a spawned viewer stays open, a served one serves until :meth:`stop`."""
        if not self._closed:
            self._closed = True
            self.rec.flush()
            self.rec.disconnect()

    def stop(self) -> None:
        """Close and stop a served web viewer."""
        self.close()
        process, self.viewer_process = self.viewer_process, None
        stop_served(process, self.mode)
