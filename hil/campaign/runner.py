"""``hil campaign``: every run of a SPEC mapped over a dask.distributed cluster, gathered as they complete
into OUT/runs.parquet (rewritten every few seconds, so an interrupted campaign keeps what it did and
``--resume`` goes on from there), then OUT/summary.json and OUT/campaign.html."""

from __future__ import annotations

import shutil
import signal
import sys
import time
import uuid
from datetime import datetime, timezone
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import Any

import yaml

from hil.campaign.campaign_report import write_campaign_report
from hil.campaign.cluster import open_client
from hil.campaign.entries import summary_entries
from hil.campaign.kinds import KINDS, Kind, Row
from hil.campaign.runs import ERROR, SWEEP_PREFIX, failed_row, task_columns
from hil.campaign.spec import DEFAULT_KIND, Campaign, SpecError, load_campaign
from hil.campaign.swing_summary import summarise, write_summary
from hil.campaign.table import RUNS_NAME, read_runs, write_runs
from hil.campaign.task import RunTask
from hil.campaign.workers import costly_defaults
from hil.outputs.record import run_record
from hil.trial.stop_signals import STOP_SIGNALS

CHECKPOINT_S = 5.0  # runs.parquet is rewritten at most this often while runs complete
SPEC_COPY = "campaign.yaml"


def made_kind(out: Path) -> str | None:
    """The kind of the campaign that made OUT, from its SPEC copy (None without a readable copy)."""
    try:
        data = yaml.safe_load((out / SPEC_COPY).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError):
        return None
    return data.get("kind", DEFAULT_KIND) if isinstance(data, dict) else None


def resumed_rows(campaign: Campaign, out: Path) -> list[dict[str, Any]]:
    """The rows of OUT/runs.parquet that the campaign can keep: done runs whose seed and swept values are
    the campaign's (a row that is not is an error: OUT belongs to another SPEC, as it does when the SPEC
    that made it was of another kind); failed runs are run again."""
    made = made_kind(out)
    if made is not None and made != campaign.spec.kind:
        raise SpecError(f"{out / SPEC_COPY}: the runs in {out} are of kind {made}, {campaign.path} of kind "
                        f"{campaign.spec.kind}: resume with the SPEC that made them, or use another --out")
    plan = {task.id: task for task in campaign.tasks}
    kept = []
    for row in read_runs(out):
        task = plan.get(row.get("id"))
        expected = {} if task is None else task_columns(task)
        extra = [k for k, v in row.items() if k.startswith(SWEEP_PREFIX) and k not in expected and v is not None]
        if task is None or extra or {k: row.get(k) for k in expected} != expected:
            raise SpecError(f"{out / RUNS_NAME}: run {row.get('id')} is not one of {campaign.path} (its seed or "
                            "swept values differ): resume with the SPEC that made it, or use another --out")
        if row.get(ERROR) is None:
            kept.append(row)
    return kept


class Interrupted(BaseException):  # as KeyboardInterrupt: no "except Exception" catches it
    """A stop signal during the runs: the campaign keeps the rows it has."""


@contextmanager
def stop_signals() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted` in the main thread (nothing here commands a
    table: unwinding is safe, and runs.parquet is written on the way out)."""
    def interrupt(signum: int, frame: FrameType | None) -> None:
        raise Interrupted(signal.Signals(signum).name)

    previous = {sig: signal.signal(sig, interrupt) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _progress(total: int, done: int):
    from rich.console import Console  # the bar only for a campaign run in a terminal
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    progress = Progress(TextColumn("campaign"), BarColumn(), MofNCompleteColumn(), TextColumn("runs,"),
                        TextColumn("{task.fields[failed]} failed,"), TextColumn("ETA"), TimeRemainingColumn(),
                        console=Console(stderr=True))
    return progress, progress.add_task("runs", total=total, completed=done, failed=0)


def gather(client, run: Callable[[RunTask], Row], tasks: list[RunTask], rows: list[Row], out: Path) -> None:
    """Map ``run`` (a kind's run) over ``tasks`` on the client's cluster; each row appended to ``rows`` as its run
    completes (a run whose task is lost is a row with its error), runs.parquet rewritten on the way."""
    from distributed import as_completed  # see hil.campaign.cluster.open_client

    batch = uuid.uuid4().hex[:8]  # keys of their own: another campaign on a shared scheduler has the same ids
    futures = client.map(run, tasks, key=[f"campaign-{batch}-{t.id}" for t in tasks])
    task_of = {f.key: t for f, t in zip(futures, tasks)}
    progress, bar = _progress(len(rows) + len(tasks), len(rows))
    failed, written = 0, time.monotonic()
    with progress:
        for future in as_completed(futures):
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - a worker lost or killed: the run's row says so
                row = failed_row(task_of[future.key], exc)
            future.release()
            rows.append(row)
            failed += row.get(ERROR) is not None
            progress.update(bar, advance=1, failed=failed)
            if time.monotonic() - written > CHECKPOINT_S:
                write_runs(out, rows)
                written = time.monotonic()


def run_campaign(spec: str | Path, out: Path, scheduler: str | None = None, workers: int | None = None,
                 resume: bool = False) -> int:
    """Run (or go on with) a campaign; returns the exit code: 0 every run done, 1 some runs failed (their
    rows say why; ``--resume`` runs them again) or a stop signal ended it (the outputs of the runs done)."""
    started = datetime.now(timezone.utc)
    campaign = load_campaign(spec)
    kind = KINDS[campaign.spec.kind]
    if (out / RUNS_NAME).exists() and not resume:
        raise SpecError(f"{out / RUNS_NAME}: exists; --resume goes on with it, or choose another --out")
    rows = resumed_rows(campaign, out) if resume else []
    done = {row["id"] for row in rows}
    pending = [task for task in campaign.tasks if task.id not in done]
    with open_client(scheduler, workers) as (client, info):
        out.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(campaign.path, out / SPEC_COPY)
        print(f"hil: campaign of {len(campaign.tasks)} runs ({len(pending)} to do) on {info.scheduler}, "
              f"{info.workers} workers, dashboard {info.dashboard}", file=sys.stderr)
        if scheduler and (warning := costly_defaults(client)):
            print(warning, file=sys.stderr)
        interrupted = None
        try:
            with stop_signals():
                gather(client, kind.run, pending, rows, out)
        except Interrupted as exc:
            interrupted = str(exc)
        finally:
            write_runs(out, rows)
    summary = {"spec": campaign.spec.as_dict(), **summarise(campaign.points, rows, info.as_dict(), kind.point_summary,
                                                            summary_entries(campaign.tasks)),
               "record": {**run_record({}, campaign.path.read_text(), started, datetime.now(timezone.utc)),
                          "spec_path": str(campaign.path)}}
    write_summary(out, summary)
    write_campaign_report(out, summary, rows, kind.section)
    print(summary_text(summary, out, kind))
    if interrupted:
        print(f"hil: campaign interrupted ({interrupted}): {len(rows)} of {len(campaign.tasks)} runs in "
              f"{out / RUNS_NAME}; --resume goes on", file=sys.stderr)
    return 1 if summary["failed"] or interrupted else 0


def summary_text(summary: dict[str, Any], out: Path, kind: Kind) -> str:
    """The console summary: the campaign's counts, then each sweep point's lines (the kind's statistics)."""
    cluster = summary["cluster"]
    head = f"campaign: {summary['runs']} runs, {summary['failed']} failed, on {cluster['workers']} workers; outputs in {out}"
    return "\n".join([head] + [line for p in summary["points"] for line in kind.lines(p)])
