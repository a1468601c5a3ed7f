"""The dask.distributed cluster a campaign runs on: a LocalCluster on this machine (scheduler, workers,
nannies and dashboard on 127.0.0.1 only), or an existing scheduler (``--scheduler tcp://host:8786``)."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from hil.campaign.workers import WORKER_CONFIG
from hil.config import InputError

LOOPBACK = "127.0.0.1"
CONNECT_TIMEOUT_S = 20.0
WORKERS_TIMEOUT_S = 120.0  # an existing cluster: how long to wait for --workers N to join


class ClusterError(InputError, ValueError):
    """A cluster that cannot be reached or started as asked."""


@dataclass(frozen=True)
class ClusterInfo:
    scheduler: str
    workers: int
    dashboard: str | None

    def as_dict(self) -> dict:
        return {"scheduler": self.scheduler, "workers": self.workers}


def default_workers() -> int:
    """One single-threaded worker process per core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


@contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[tuple[object, ClusterInfo]]:
    """A connected ``distributed.Client`` and what it runs on; a LocalCluster of ``workers`` processes
    (default: :func:`default_workers`) unless ``scheduler`` names one, whose ``workers`` are waited for."""
    import dask  # dask and distributed (about 1 s) only when a campaign runs
    from distributed import Client, LocalCluster

    if workers is not None and workers < 1:
        raise ClusterError(f"--workers: expected at least 1, got {workers}")
    if scheduler is None:
        with dask.config.set(WORKER_CONFIG):  # the nannies hand their config to the worker processes
            cluster = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1, processes=True,
                                   host=LOOPBACK, scheduler_port=0, dashboard_address=f"{LOOPBACK}:0",
                                   worker_dashboard_address=None, silence_logs=logging.ERROR)
        try:
            with Client(cluster) as client:
                yield client, _info(client)
        finally:
            cluster.close()
        return
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ClusterError(f"--scheduler {scheduler}: cannot connect: {' '.join(str(exc).split())}") from None
    with client:
        try:
            client.wait_for_workers(workers or 1, timeout=WORKERS_TIMEOUT_S)
        except TimeoutError:
            raise ClusterError(f"--scheduler {scheduler}: fewer than {workers or 1} workers joined in "
                               f"{WORKERS_TIMEOUT_S:g} s (start them with `hil worker {scheduler}`)") from None
        yield client, _info(client)


def _info(client) -> ClusterInfo:
    return ClusterInfo(client.scheduler.address, len(client.scheduler_info()["workers"]), client.dashboard_link)
