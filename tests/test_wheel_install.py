"""A regular wheel install (no checkout, no editable finder) runs the default trial from an empty directory."""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hil/", "drivers/", "emulators/")


def _tracked() -> list[str]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True).stdout
    return [name for name in out.decode().split("\0") if name]


def _in_wheel(name: str) -> str | None:
    """Where a tracked file belongs in the wheel, or None for files that stay out of it."""
    if name.startswith(PACKAGES) and name.endswith(".py"):
        return name
    if name.startswith("configs/") and name.endswith((".py", ".yaml", ".dbc")):
        return "hil/" + name
    return None


@pytest.mark.slow
def test_wheel_installs_the_configs_and_runs_the_default_trial_from_an_empty_directory(tmp_path):
    src, dist, venv, empty, out = (tmp_path / d for d in ("src", "dist", "venv", "empty", "out"))
    tracked = _tracked()
    for name in tracked:  # build from a copy: the build leaves nothing in the repository
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, src / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index",
                    "-w", str(dist), str(src)], check=True)
    (wheel,) = dist.glob("turntable_hil-*.whl")
    expected = {target for name in tracked if (target := _in_wheel(name))}
    assert expected <= set(zipfile.ZipFile(wheel).namelist())

    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", "--no-index",
                    str(wheel)], check=True)
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                               check=True, capture_output=True, text=True).stdout.strip())
    # the third-party dependencies: this interpreter's import path less the checkout, after the venv's own
    deps = [p for p in sys.path if p and Path(p).is_dir() and Path(p).resolve() != ROOT]
    (site / "zz_test_dependencies.pth").write_text("".join(f"{path}\n" for path in deps))

    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    where = subprocess.run([python, "-c", "import hil, hil.configs, drivers, emulators as e; "
                            "print(hil.__file__, hil.configs.__file__, drivers.__file__, e.__file__)"],
                           cwd=empty, env=env, check=True, capture_output=True, text=True).stdout.split()
    assert all(Path(path).is_relative_to(site) for path in where), where
    run = subprocess.run([venv / "bin" / "hil", "run", "--duration", "5", "--speed", "max", "--viewer", "none",
                          "--out", str(out)], cwd=empty, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 3, run.stderr  # completed; 5 s cannot meet the default trial's 600 s limits
    result = json.loads((out / "result.json").read_text())
    assert result["ended"] == "completed" and result["streams"]["aligned"] > 0
    assert not any(empty.iterdir())
