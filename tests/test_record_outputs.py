"""The record in every output (docs/contracts.md, "result.json" > record): calibration.json, calibration.html,
the MCAP metadata, noise.json (tests/test_history.py), campaign rows and summary; and every HTML page opens
with the same header and fits a 1400 px window in headless Chromium."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from mcap.records import Metadata
from mcap.stream_reader import StreamReader

from hil.campaign.runs import task_columns
from hil.campaign.task import RunTask
from hil.outputs.result_schema import read_result
from tests.pages import WINDOW_PX, layout_width, needs_chromium

ROOT = Path(__file__).resolve().parents[1]


def hil(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil.cli", *args], cwd=cwd, capture_output=True, text=True,
                          check=False)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """A simulated calibration, a live emulated trial, a noise run and a campaign, each with a record."""
    tmp = tmp_path_factory.mktemp("outputs")
    done = {
        "calibration": hil("calibrate", "configs/calibration_short.yaml", "--simulate", "--viewer", "none",
                           "--dut", "SN-CAL", "--operator", "kim", "--out", str(tmp / "cal")),
        "run": hil("run", "--duration", "5", "--speed", "max", "--viewer", "none", "--quiet", "--no-figures",
                   "--dut", "SN-RUN", "--station", "bay 3", "--out", str(tmp / "run")),
        "noise": hil("noise", "configs/noise_static.yaml", "--duration", "200", "--dut", "SN-NOISE",
                     "--out", str(tmp / "noise")),
    }
    spec = tmp / "spec.yaml"
    spec.write_text(yaml.safe_dump({"base": str(ROOT / "configs" / "liu2019_sim.yaml"), "runs": 2, "seed": 1,
                                    "sweep": {"trial.duration_s": [20.0], "trial.rate_hz": [10]}}))
    done["campaign"] = hil("campaign", str(spec), "--workers", "1", "--out", str(tmp / "campaign"), cwd=tmp)
    for name, run in done.items():
        assert run.returncode in (0, 3), f"{name}: {run.stderr}"
    return tmp


def test_the_trials_result_files_follow_the_schema_with_their_record(outputs):
    replay = hil("replay", str(outputs / "run"), "--viewer", "none", "--no-figures")
    assert replay.returncode in (0, 3), replay.stderr
    for run in ("cal", "run", "run/replay"):
        result = read_result(outputs / run / "result.json")
        assert result.record is not None and result.record.software_version
    assert read_result(outputs / "run" / "result.json").record.dut_serial == "SN-RUN"


def test_calibration_json_and_html_carry_the_trials_record_and_verdict(outputs):
    cal = outputs / "cal"
    record = json.loads((cal / "calibration.json").read_text())["record"]
    result = json.loads((cal / "result.json").read_text())
    assert record == result["record"] and record["dut_serial"] == "SN-CAL" and record["operator"] == "kim"
    page = (cal / "calibration.html").read_text()
    name = result["trial"]["name"]
    assert f"<h1>{name}</h1>" in page and "SN-CAL" in page and "kim" in page and record["started_utc"][:10] in page
    assert re.search(r'class="verdict (PASS|FAIL)"', page) and "Trial completed." in page
    report = (cal / "report.html").read_text()
    assert "Multi-position calibration" in report and "swinging motion" not in report


def test_the_recording_holds_the_record_at_its_start_and_the_end_time_at_its_end(outputs):
    with open(outputs / "run" / "recording.mcap", "rb") as f:
        metadata = {r.name: dict(r.metadata) for r in StreamReader(f).records if isinstance(r, Metadata)}
    result = json.loads((outputs / "run" / "result.json").read_text())["record"]
    assert metadata["record"]["dut_serial"] == "SN-RUN" and metadata["record"]["station"] == "bay 3"
    for key in ("software_version", "config_sha256", "host"):
        assert metadata["record"][key] == result[key]
    assert metadata["record"]["dut_part"] == "" and json.loads(metadata["record"]["ports"]) == result["ports"]
    assert metadata["trial_end"]["ended"] == "completed"
    assert result["started_utc"] <= metadata["record"]["started_utc"] <= metadata["trial_end"]["ended_utc"]


def test_campaign_rows_carry_the_unit_and_the_config_digest_and_the_summary_the_software(outputs):
    config = yaml.safe_load((ROOT / "configs" / "liu2019_sim.yaml").read_text())
    config["record"] = {"dut_serial": "SN-MC", "dut_part": "KVH-1750"}
    columns = task_columns(RunTask("p000-r0000", 0, 0, 7, {}, config))
    assert columns["record.dut_serial"] == "SN-MC" and columns["record.dut_part"] == "KVH-1750"
    assert len(columns["record.config_sha256"]) == 64
    summary = json.loads((outputs / "campaign" / "summary.json").read_text())
    assert summary["record"]["software_version"] and summary["record"]["spec_path"].endswith("spec.yaml")
    assert "<h1>spec</h1>" in (outputs / "campaign" / "campaign.html").read_text()


@needs_chromium
def test_every_page_opens_with_the_header_and_fits_1400_px(outputs, tmp_path):
    pages = [outputs / "cal" / "report.html", outputs / "cal" / "calibration.html", outputs / "run" / "report.html",
             outputs / "noise" / "report.html", outputs / "campaign" / "campaign.html"]
    for page in pages:
        text = page.read_text()
        assert text.index('<header class="run">') < text.index("<h1>") < text.index("</header>"), page
        assert layout_width(page, tmp_path) <= WINDOW_PX, page
