"""The Rerun viewer as a child process: the native window (``spawn``) or a web viewer (``serve``), bound
to 127.0.0.1 unless another bind address is given. Rerun's usage analytics are off in the viewers
started here unless the user turns them on (``HIL_RERUN_TELEMETRY=1``)."""

from __future__ import annotations

import atexit
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from urllib.parse import quote

TELEMETRY_ENV = "HIL_RERUN_TELEMETRY"


def telemetry_requested() -> bool:
    """Whether the user turned Rerun's usage analytics on (``HIL_RERUN_TELEMETRY=1``)."""
    return os.environ.get(TELEMETRY_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def start_viewer(mode: str, bind: str, telemetry: bool) -> tuple[subprocess.Popen, str, str | None]:
    """Start ``rerun`` (native or web) as a child process bound to ``bind``; returns (the process, its gRPC
    URL, the web viewer's address in ``serve`` mode else None)."""
    exe = rerun_executable()
    grpc_port = _free_port(bind, 9876)
    args = [exe, "--bind", bind, "--port", str(grpc_port), "--memory-limit", "50%"]
    if mode == "serve":
        web_port = _free_port(bind, 9090, exclude=grpc_port)
        args += ["--serve-web", "--web-viewer-port", str(web_port), "--server-memory-limit", "25%"]
    else:
        args += ["--expect-data-soon"]
    env = dict(os.environ)
    if not telemetry:
        # rerun 0.41 has no switch for this other than its config file (`rerun analytics disable`);
        # its analytics pipeline stays off when CI is set, so the child gets it
        env["CI"] = env.get("CI") or "1"
    process = subprocess.Popen(
        args, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        start_new_session=mode == "spawn",
    )  # fmt: skip
    local, public = _hosts(bind)
    url = None
    if not _wait_port(local, grpc_port, process, timeout=15.0):
        err = process.stderr.read().decode(errors="replace")[-2000:] if process.poll() is not None else ""
        process.kill()
        hint = " (no display? use --viewer serve or save)" if mode == "spawn" else ""
        raise RuntimeError(f"the Rerun viewer did not start{hint}: {' '.join(args)}\n{err}".rstrip())
    if mode == "serve":
        threading.Thread(target=_drain, args=(process.stderr,), daemon=True).start()
        atexit.register(_terminate, process)
        grpc_public = f"rerun+http://{_url_host(public)}:{grpc_port}/proxy"
        url = f"http://{_url_host(public)}:{web_port}/?url={quote(grpc_public, safe='')}"
        print(f"Rerun web viewer: {url}", file=sys.stderr, flush=True)
    else:
        process.stderr.close()
    return process, f"rerun+http://{_url_host(local)}:{grpc_port}/proxy", url


def stop_served(process: subprocess.Popen | None, mode: str) -> None:
    """Stop the web viewer of ``serve`` mode (a spawned native viewer stays open)."""
    if process is not None and mode == "serve" and process.poll() is None:
        process.terminate()
        try:
            process.wait(5.0)
        except subprocess.TimeoutExpired:
            process.kill()


def rerun_executable() -> str:
    """The ``rerun`` binary of the installed rerun-sdk (the one whose version matches the SDK)."""
    try:
        import rerun_cli  # the viewer's binary, only when a viewer is started

        path = Path(rerun_cli.__file__).parent / "rerun"
        if path.exists():
            return str(path)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if found is None:
        raise RuntimeError("the rerun viewer executable was not found: reinstall rerun-sdk (pip install rerun-sdk)")
    return found


def _hosts(bind: str) -> tuple[str, str]:
    """(address this process connects to, host name a browser is given) for a server bound to ``bind``."""
    if bind in ("0.0.0.0", ""):
        return "127.0.0.1", socket.gethostname()
    if bind == "::":
        return "::1", socket.gethostname()
    return bind, bind


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def _free_port(bind: str, preferred: int, exclude: int | None = None) -> int:
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    for port in (preferred, 0):
        if port and port == exclude:
            continue
        with socket.socket(family, socket.SOCK_STREAM) as s:
            try:
                s.bind((bind, port))
            except OSError:
                continue
            return s.getsockname()[1]
    raise RuntimeError(f"no free TCP port on {bind}")


def _wait_port(host: str, port: int, process: subprocess.Popen, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            return False
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return True
        except OSError:
            time.sleep(0.1)
    return False


def _drain(stream) -> None:
    for _ in iter(lambda: stream.read(4096), b""):
        pass


def _terminate(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
