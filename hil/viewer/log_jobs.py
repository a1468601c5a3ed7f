"""The logging thread of a Rerun view (:class:`~hil.viewer.trial_viewer.TrialViewer`,
:class:`~hil.viewer.fixture_view.FixtureView`): jobs run in order on one background thread, each followed by
``after_each`` (a view's rows due to its sinks), ``at_end`` once the queue is closed. A job that raises never
stops the trial: the first error is kept and logged once."""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable

log = logging.getLogger(__name__)

QUEUE_ITEMS = 1024  # jobs waiting for the logging thread before live calls are dropped


class LogJobs:
    """The background thread of the view ``what`` (named in its one warning), started at once."""

    def __init__(self, name: str, what: str, after_each: Callable[[], None], at_end: Callable[[], None]) -> None:
        self.error: BaseException | None = None  # the first error a job met
        self.queue: queue.Queue[Callable[[], object] | None] = queue.Queue(QUEUE_ITEMS)
        self._what = what
        self._after_each = after_each
        self._at_end = at_end
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: Callable[[], object], block: bool) -> bool:
        """Queue ``job``; False when the queue is full and ``block`` is not asked (the job is dropped)."""
        try:
            self.queue.put(job, block=block)
        except queue.Full:
            return False
        return True

    def run(self, job: Callable[[], object]) -> None:
        """Run ``job`` here, its error kept rather than raised: logging must never stop a trial."""
        try:
            job()
        except Exception as exc:  # noqa: BLE001 - logging must never stop a trial
            if self.error is None:
                self.error = exc
                log.warning("Rerun logging error in %s (further errors not reported): %s", self._what, exc)

    def stop(self) -> None:
        """Run what is queued and ``at_end``, wait for the thread, and warn once more if a job failed."""
        self.queue.put(None)
        self._thread.join()
        if self.error is not None:
            log.warning("Rerun logging of %s failed: %s", self._what, self.error)

    def _work(self) -> None:
        while (job := self.queue.get()) is not None:
            self.run(job)
            self._after_each()
        self.run(self._at_end)
