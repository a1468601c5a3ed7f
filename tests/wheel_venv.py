"""A fresh virtual environment with the project installed from a wheel built from its tracked files (no
checkout on the path, no editable finder): what a lab gets from ``pip install``. The third-party packages come
from this interpreter's path, through a .pth file after the venv's own site-packages, so that nothing is
downloaded; the project itself only from the wheel."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class WheelVenv:
    wheel: Path
    python: Path
    site: Path
    env: dict[str, str]  # this process's environment without the variables that would point at the checkout

    def bin(self, name: str) -> Path:
        return self.python.parent / name


def tracked() -> list[str]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True).stdout
    return [name for name in out.decode().split("\0") if name]


def install_wheel(tmp_path: Path) -> WheelVenv:
    """Build the wheel from a copy of the tracked files (the build leaves nothing in the repository) and
    install it into a new venv under ``tmp_path``."""
    src, dist, venv = (tmp_path / d for d in ("src", "dist", "venv"))
    for name in tracked():
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, src / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index",
                    "-w", str(dist), str(src)], check=True)
    (wheel,) = dist.glob("turntable_hil-*.whl")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", "--no-index",
                    str(wheel)], check=True)
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                               check=True, capture_output=True, text=True).stdout.strip())
    deps = [p for p in sys.path if p and Path(p).is_dir() and Path(p).resolve() != ROOT]
    (site / "zz_test_dependencies.pth").write_text("".join(f"{path}\n" for path in deps))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    return WheelVenv(wheel, python, site, env)
