"""A third party's IMU codec, from a tiny package installed in a temporary venv with nothing but its module and
its entry point (tests/data/demo_imu_plugin): accepted by the config, decoded by ``hil decode NAME`` and emulated
by ``hil run``, with no change to the project."""

import functools
import json
import operator
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = ROOT / "tests" / "data" / "demo_imu_plugin"


def frame(counter: int, dtheta: tuple, dv: tuple) -> bytes:
    """A demo-imu frame written from its description: DM, u16 counter, 6 x i32, status, xor of all before."""
    body = b"DM" + counter.to_bytes(2, "big") + b"".join(v.to_bytes(4, "big", signed=True) for v in dtheta + dv)
    body += b"\x00"
    return body + bytes([functools.reduce(operator.xor, body)])


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    """A venv that sees this checkout and its dependencies, and has the plug-in installed."""
    tmp = tmp_path_factory.mktemp("plugin")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                               check=True, capture_output=True, text=True).stdout.strip())
    paths = [str(ROOT)] + [p for p in sys.path if p and Path(p).is_dir() and Path(p).resolve() != ROOT]
    (site / "zz_test_dependencies.pth").write_text("".join(f"{path}\n" for path in paths))
    source = tmp / "src"
    shutil.copytree(PLUGIN, source)  # the build writes into its source: not into the checkout
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps",
                    "--no-build-isolation", "--no-index", str(source)], check=True)
    return python, tmp


def run(python: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    return subprocess.run([str(python), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def test_the_plugin_is_not_seen_here():
    from drivers.registry import IMU_CODECS

    assert "demo-imu" not in IMU_CODECS.names()


def test_a_third_party_codec_is_configured_decoded_and_emulated(venv):
    python, tmp = venv
    check = run(python, "-c", "from hil.config import parse_config; from drivers.registry import imu_codec; "
                "c = parse_config({'trial': {'duration_s': 1}, 'site': {'latitude_deg': 32}, "
                "'imu': {'protocol': 'demo-imu', 'options': {'dv_lsb_mps': 1e-7}}}); "
                "print(imu_codec(c.imu, 200).options.dv_lsb_mps)", cwd=tmp)
    assert check.returncode == 0 and check.stdout.strip() == "1e-07", check.stderr

    (tmp / "cap.bin").write_bytes(b"\xff" + b"".join(frame(k, (1000, -1, 0), (0, 0, 490332)) for k in (7, 8, 10)))
    decode = run(python, "-m", "hil.cli", "decode", "demo-imu", "cap.bin", "--out", "cap.csv", cwd=tmp)
    assert decode.returncode == 0, decode.stderr
    assert json.loads(decode.stdout.splitlines()[-1]) == {"frames": 3, "corrupt": 0, "skipped_bytes": 1, "gaps": 1,
                                                          "invalid": 0}
    assert (tmp / "cap.csv").read_text().splitlines()[1] == "7,7,1000,-1,0,0,0,490332,0,1"

    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["imu"]["protocol"] = "demo-imu"
    cfg["output"]["limits"] = {}
    (tmp / "demo.yaml").write_text(yaml.safe_dump(cfg))
    trial = run(python, "-m", "hil.cli", "run", "demo.yaml", "--duration", "20", "--speed", "max", "--quiet",
                "--no-figures", "--viewer", "none", "--out", "out", cwd=tmp)
    assert trial.returncode == 0, trial.stderr
    result = json.loads((tmp / "out" / "result.json").read_text())
    assert result["streams"]["imu_frames"] == result["streams"]["aligned"] == 20 * 200
    assert result["streams"]["corrupt"] == 0 and result["estimate"]["observable"]
