"""The campaign's worker settings: the dask config a LocalCluster's workers get, ``hil worker`` (dask workers
started with it for an existing cluster), and the one-line warning for a cluster whose workers lack it."""

from __future__ import annotations

import os

from hil.inputs import InputError

# Two of dask's worker defaults cost a short numpy-bound run dearly (benchmarks/campaign_speed.py): the
# statistical profiler (every thread's stack every 10 ms) and MALLOC_TRIM_THRESHOLD_=65536, which hands every
# freed sample chunk back to the OS (5x the page faults, 1.6-2.5x the run time; glibc's own dynamic threshold,
# what None leaves, measured best: 65536, 128 MiB and unset compared); the memory a run takes is bounded by
# the simulation's chunk.
WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                 "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
TRIM = "MALLOC_TRIM_THRESHOLD_"


def worker_settings() -> dict:
    """This worker process's settings of :data:`WORKER_CONFIG` (run on every worker by ``client.run``)."""
    import dask  # on the worker, which has it loaded

    return {"profile": bool(dask.config.get("distributed.worker.profile.enabled")), "trim": os.environ.get(TRIM)}


def costly_defaults(client) -> str | None:
    """One line naming the workers of the client's cluster that run with dask's costly defaults (the
    profiler on, MALLOC_TRIM_THRESHOLD_ set) and how to start them without; None when none does."""
    settings = client.run(worker_settings)
    profiled = sum(s["profile"] for s in settings.values())
    trimmed = sum(s["trim"] is not None for s in settings.values())
    if not profiled and not trimmed:
        return None
    found = [f"{n} of {len(settings)} with {what}" for n, what in
             ((profiled, "the statistical profiler on"), (trimmed, f"{TRIM} set")) if n]
    return (f"hil: warning: the cluster's workers run with dask's costly defaults ({', '.join(found)}): runs take up "
            f"to twice as long; start them with `hil worker {client.scheduler.address} --nworkers N` (docs/campaign.md)")


def worker_arguments(scheduler: str, nworkers: int, host: str | None) -> list[str]:
    """The ``dask worker`` arguments of ``hil worker``: ``nworkers`` single-threaded processes (with a
    ``host``, their listening sockets and metrics on it only)."""
    if nworkers < 1:
        raise InputError(f"--nworkers: expected at least 1, got {nworkers}")
    args = [scheduler, "--nworkers", str(nworkers), "--nthreads", "1"]
    return args + ["--host", host, "--dashboard-address", f"{host}:0"] if host else args


def run_workers(scheduler: str, nworkers: int, host: str | None = None) -> int:
    """Run ``dask worker`` in this process with :data:`WORKER_CONFIG` (its nannies hand it to the worker
    processes) until it ends (a signal); its exit code. Workers that cannot start (the scheduler not reached
    within dask's connect timeout, an address taken) are an :class:`InputError` naming the cause."""
    import dask  # dask and distributed only for hil worker
    from distributed.cli.dask_worker import main

    with dask.config.set(WORKER_CONFIG):
        try:
            main(worker_arguments(scheduler, nworkers, host), prog_name="hil worker", standalone_mode=False)
        except SystemExit as exc:
            return exc.code if isinstance(exc.code, int) else 1
        except RuntimeError as exc:  # dask's "Nanny failed to start.", from the cause
            cause = exc.__cause__ or exc
            raise InputError(f"{scheduler}: cannot start the workers: {' '.join(str(cause).split())}") from None
    return 0
