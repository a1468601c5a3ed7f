"""A regular wheel install (no checkout, no editable finder) runs the default trial from an empty directory."""

import json
import subprocess
import zipfile
from pathlib import Path

import pytest

from tests.wheel_venv import install_wheel, tracked

PACKAGES = ("hil/", "drivers/", "emulators/")


def _in_wheel(name: str) -> str | None:
    """Where a tracked file belongs in the wheel, or None for files that stay out of it."""
    if name.startswith(PACKAGES) and name.endswith(".py"):
        return name
    if name.startswith("configs/") and name.endswith((".py", ".yaml", ".dbc")):
        return "hil/" + name
    return None


@pytest.mark.slow
def test_wheel_installs_the_configs_and_runs_the_default_trial_from_an_empty_directory(tmp_path):
    venv = install_wheel(tmp_path)
    expected = {target for name in tracked() if (target := _in_wheel(name))}
    assert expected <= set(zipfile.ZipFile(venv.wheel).namelist())
    empty, out = tmp_path / "empty", tmp_path / "out"
    empty.mkdir()
    where = subprocess.run([venv.python, "-c", "import hil, hil.configs, drivers, emulators as e; "
                            "print(hil.__file__, hil.configs.__file__, drivers.__file__, e.__file__)"],
                           cwd=empty, env=venv.env, check=True, capture_output=True, text=True).stdout.split()
    assert all(Path(path).is_relative_to(venv.site) for path in where), where
    run = subprocess.run([venv.bin("hil"), "run", "--duration", "5", "--speed", "max", "--viewer", "none",
                          "--out", str(out)], cwd=empty, env=venv.env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 3, run.stderr  # completed; 5 s cannot meet the default trial's 600 s limits
    result = json.loads((out / "result.json").read_text())
    assert result["ended"] == "completed" and result["streams"]["aligned"] > 0
    assert not any(empty.iterdir())
