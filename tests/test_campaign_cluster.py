"""Campaigns on real dask.distributed clusters: a LocalCluster of 2 worker processes and an existing scheduler
with its workers started here, both on 127.0.0.1 only, give the same runs.parquet; --resume completes a
partial table to the same rows; a worker killed mid-campaign loses no run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml

from hil.campaign.cluster import open_client
from hil.campaign.runs import failed_row
from hil.campaign.spec import load_campaign
from hil.campaign.table import read_runs, write_runs

ROOT = Path(__file__).resolve().parent.parent
LOOPBACK_HEX = "0100007F"  # 127.0.0.1 as /proc/net/tcp writes it
pytestmark = pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc")


def _tree(pid: int) -> list[int]:
    """``pid`` and its descendants."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        found.append(p)
        for task in Path(f"/proc/{p}/task").glob("*/children"):
            todo += [int(c) for c in task.read_text().split()]
    return found


def listening(pid: int) -> list[tuple[str, int]]:
    """(local address as /proc writes it, port) of every listening TCP socket held by ``pid``'s tree."""
    inodes = set()
    for p in _tree(pid):
        for fd in Path(f"/proc/{p}/fd").iterdir():
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            address, port = fields[1].rsplit(":", 1)
            if fields[3] == "0A" and fields[9] in inodes:
                found.append((address, int(port, 16)))
    return found


def test_local_cluster_scheduler_workers_and_dashboard_listen_on_loopback_only():
    with open_client(None, 2) as (_, info):
        sockets = listening(os.getpid())
        ports = {port for _, port in sockets}
        assert info.workers == 2 and info.scheduler.startswith("tcp://127.0.0.1:")
        assert int(info.scheduler.rsplit(":", 1)[1]) in ports
        assert int(info.dashboard.split(":")[2].split("/")[0]) in ports
        assert len(sockets) >= 4  # scheduler, dashboard, two workers at least
        assert {address for address, _ in sockets} == {LOOPBACK_HEX}


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def _campaign(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "campaign", *args], check=False, cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc


@pytest.fixture
def existing_cluster(tmp_path):
    """A scheduler and two worker processes started as `dask scheduler` / `dask worker` would be, each of
    them on 127.0.0.1 (a worker serves its metrics on --dashboard-address, 0.0.0.0 unless told)."""
    info = tmp_path / "scheduler.json"
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", "0", "--dashboard-address", "127.0.0.1:0", "--scheduler-file", str(info)],
                                 cwd=tmp_path, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file", str(info),
                                "--host", "127.0.0.1", "--nworkers", "2", "--nthreads", "1",
                                "--dashboard-address", "127.0.0.1:0"],
                               cwd=tmp_path, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not info.exists() or not info.read_text():
            assert time.monotonic() < deadline and scheduler.poll() is None, "the scheduler did not start"
            time.sleep(0.2)
        yield json.loads(info.read_text())["address"], (scheduler, workers)
    finally:
        for proc in (workers, scheduler):
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()


def test_local_and_existing_clusters_give_identical_rows_and_resume_completes_a_partial_table(tmp_path,
                                                                                            existing_cluster):
    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump({"base": str(ROOT / "configs" / "liu2019_sim.yaml"), "runs": 2, "seed": 3,
                                    "sweep": {"turntable.motion.axes.inner.amplitude_deg": [5, 13],
                                              "trial.duration_s": [20.0, 40.0], "trial.rate_hz": [10]}}))
    _campaign(str(spec), "--workers", "2", "--out", "local", cwd=tmp_path)
    address, processes = existing_cluster
    _campaign(str(spec), "--scheduler", address, "--workers", "2", "--out", "existing", cwd=tmp_path)
    local, existing = (pq.read_table(tmp_path / d / "runs.parquet") for d in ("local", "existing"))
    assert local.num_rows == 8 and local.column("error").null_count == 8
    assert local.column("id").to_pylist() == [t.id for t in load_campaign(spec).tasks]
    assert local.equals(existing)
    cluster = json.loads((tmp_path / "existing" / "summary.json").read_text())["cluster"]
    assert cluster == {"scheduler": address, "workers": 2}
    local_cluster = json.loads((tmp_path / "local" / "summary.json").read_text())["cluster"]
    assert local_cluster["workers"] == 2 and local_cluster["scheduler"].startswith("tcp://127.0.0.1:")
    assert (tmp_path / "local" / "campaign.html").read_text().count("data:image/png;base64,") == 4
    for proc in processes:
        assert {a for a, _ in listening(proc.pid)} == {LOOPBACK_HEX}

    rows = read_runs(tmp_path / "local")
    partial = tmp_path / "partial"
    partial.mkdir()
    tasks = {t.id: t for t in load_campaign(spec).tasks}
    write_runs(partial, rows[:3] + [failed_row(tasks[rows[3]["id"]], "KilledWorker: lost")])
    proc = _campaign(str(spec), "--scheduler", address, "--out", "partial", "--resume", cwd=tmp_path)
    assert "8 runs (5 to do)" in proc.stderr
    assert pq.read_table(partial / "runs.parquet").equals(local)


def test_sigterm_ends_a_campaign_with_its_rows_kept_and_exit_1(tmp_path):
    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump({"base": str(ROOT / "configs" / "liu2019_sim.yaml"), "runs": 2000, "seed": 1,
                                    "sweep": {"trial.duration_s": [20.0], "trial.rate_hz": [10]}}))
    proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "campaign", str(spec), "--workers", "2", "--out", "o"],
                            cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "o" / "runs.parquet").exists():  # the first checkpoint: some runs are done
            assert time.monotonic() < deadline and proc.poll() is None, proc.stderr.read() if proc.poll() else ""
            time.sleep(0.2)
        proc.terminate()
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 1
    done = len(read_runs(tmp_path / "o"))
    assert 0 < done < 2000 and f"campaign interrupted (SIGTERM): {done} of 2000 runs" in err
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["runs"] == done and summary["failed"] == 0


def _busy_worker(client) -> str | None:
    """The address of a worker the scheduler has given a campaign's run to, if any."""
    return next((worker for worker, keys in client.processing().items()
                 if any(str(key).startswith("campaign-") for key in keys)), None)


def test_a_worker_killed_mid_campaign_leaves_every_run_a_row(tmp_path, existing_cluster):
    from distributed import Client

    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump({"base": str(ROOT / "configs" / "noise_static.yaml"), "kind": "noise", "runs": 8,
                                    "seed": 2, "sweep": {"trial.duration_s": [600.0]}}))
    address, (_, workers) = existing_cluster
    proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "campaign", str(spec), "--scheduler", address,
                             "--workers", "2", "--out", "o"], cwd=tmp_path, env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        with Client(address, timeout=20) as client:
            deadline = time.monotonic() + 60
            while (busy := _busy_worker(client)) is None:
                assert time.monotonic() < deadline and proc.poll() is None, "no run reached a worker"
                time.sleep(0.1)
            time.sleep(0.5)  # into the run: its worker imports and simulates
            pid = client.run(os.getpid, workers=[busy])[busy]
            assert any(str(key).startswith("campaign-") for key in client.processing()[busy])  # killed mid-run
            assert pid in _tree(workers.pid)  # one of the worker processes this test started
            os.kill(pid, signal.SIGKILL)
        out, err = proc.communicate(timeout=180)
    finally:
        proc.kill()
    assert proc.returncode in (0, 1), err  # 1: some run failed with the lost worker (its row says so)
    table = pq.read_table(tmp_path / "o" / "runs.parquet")
    rows = table.to_pylist()
    assert [row["id"] for row in rows] == [t.id for t in load_campaign(spec).tasks]
    failed = [row for row in rows if row["error"] is not None]
    assert all(row["error"].strip() for row in failed) and (proc.returncode == 1) == bool(failed)
    assert all(row["accel.vrw_m_per_s_per_sqrt_h.0"] is not None for row in rows if row["error"] is None)
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["runs"] == 8 and summary["failed"] == len(failed)
    assert f"campaign: 8 runs, {len(failed)} failed" in out
