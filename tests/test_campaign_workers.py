"""``hil worker`` and the warning of ``hil campaign --scheduler``: a real scheduler on 127.0.0.1 with a plain
``dask worker`` (dask's defaults: the profiler on, MALLOC_TRIM_THRESHOLD_ set) is named in one line with the
command that starts workers without them; the same cluster's workers started by ``hil worker`` are not."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from hil.campaign.workers import costly_defaults, worker_arguments, worker_settings
from hil.cli import build_parser, main
from tests.test_campaign_cluster import LOOPBACK_HEX, ROOT, _env, listening

pytestmark = pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc")


def test_worker_arguments_give_single_threaded_processes_on_the_host_asked():
    args = build_parser().parse_args(["worker", "tcp://127.0.0.1:8786", "--nworkers", "3", "--host", "127.0.0.1"])
    assert (args.scheduler, args.nworkers, args.host) == ("tcp://127.0.0.1:8786", 3, "127.0.0.1")
    assert worker_arguments(args.scheduler, args.nworkers, args.host) == [
        "tcp://127.0.0.1:8786", "--nworkers", "3", "--nthreads", "1", "--host", "127.0.0.1",
        "--dashboard-address", "127.0.0.1:0"]
    default = build_parser().parse_args(["worker", "tcp://10.0.0.5:8786"])
    assert worker_arguments(default.scheduler, default.nworkers, default.host) == [
        "tcp://10.0.0.5:8786", "--nworkers", "1", "--nthreads", "1"]


def test_worker_refuses_no_workers_in_one_line_exit_2(capsys):
    assert main(["worker", "tcp://127.0.0.1:8786", "--nworkers", "0"]) == 2
    err = capsys.readouterr().err
    assert err == "hil: error: --nworkers: expected at least 1, got 0\n"


def test_worker_without_a_scheduler_is_one_line_exit_2(tmp_path):
    env = {**_env(), "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"}
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "worker", "tcp://127.0.0.1:1", "--host", "127.0.0.1"],
                          check=False, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    last = proc.stderr.splitlines()[-1]
    assert last.startswith("hil: error: tcp://127.0.0.1:1: cannot start the workers: Timed out trying to connect")
    assert "Traceback" not in proc.stderr


def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, *args], cwd=cwd, env=_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _stop(*procs: subprocess.Popen) -> None:
    for proc in procs:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()


@pytest.fixture
def scheduler(tmp_path):
    """A scheduler on 127.0.0.1, started as `dask scheduler` would be; its address."""
    info = tmp_path / "scheduler.json"
    proc = _start(["-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                   "--dashboard-address", "127.0.0.1:0", "--scheduler-file", str(info)], tmp_path)
    try:
        deadline = time.monotonic() + 60
        while not info.exists() or not info.read_text():
            assert time.monotonic() < deadline and proc.poll() is None, "the scheduler did not start"
            time.sleep(0.2)
        yield json.loads(info.read_text())["address"]
    finally:
        _stop(proc)


def _campaign(spec: Path, address: str, out: str, cwd: Path) -> str:
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "campaign", str(spec), "--scheduler", address,
                           "--workers", "1", "--out", out], check=False, cwd=cwd, env=_env(), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc.stderr


def test_campaign_warns_of_plain_dask_workers_and_not_of_hil_workers(tmp_path, scheduler):
    from distributed import Client

    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump({"base": str(ROOT / "configs" / "liu2019_sim.yaml"), "runs": 1, "seed": 1,
                                    "sweep": {"trial.duration_s": [20.0], "trial.rate_hz": [10]}}))
    plain = _start(["-m", "distributed.cli.dask_worker", scheduler, "--host", "127.0.0.1", "--nworkers", "1",
                    "--nthreads", "1", "--dashboard-address", "127.0.0.1:0"], tmp_path)
    try:
        err = _campaign(spec, scheduler, "plain", tmp_path)
    finally:
        _stop(plain)
    warning = [line for line in err.splitlines() if "warning" in line]
    assert warning == [f"hil: warning: the cluster's workers run with dask's costly defaults (1 of 1 with the "
                       f"statistical profiler on, 1 of 1 with MALLOC_TRIM_THRESHOLD_ set): runs take up to twice as "
                       f"long; start them with `hil worker {scheduler} --nworkers N` (docs/campaign.md)"]

    ours = _start(["-m", "hil.cli", "worker", scheduler, "--nworkers", "2", "--host", "127.0.0.1"], tmp_path)
    try:
        with Client(scheduler, timeout=20) as client:
            client.wait_for_workers(2, timeout=60)
            assert set(client.scheduler_info()["workers"]) == set(client.run(worker_settings))
            assert all(w["nthreads"] == 1 for w in client.scheduler_info()["workers"].values())
            assert list(client.run(worker_settings).values()) == [{"profile": False, "trim": None}] * 2
            assert costly_defaults(client) is None
        err = _campaign(spec, scheduler, "ours", tmp_path)
        assert "warning" not in err and "2 workers" in err
        assert {address for address, _ in listening(ours.pid)} == {LOOPBACK_HEX}
    finally:
        _stop(ours)
