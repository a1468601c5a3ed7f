"""The trial history (docs/history.md): trials filed after their outputs, a unit's bias repeatability
computed here independently from its result.json files, history.html in a browser, the schema migrated, and a
history that cannot be written costing one warning line, never the trial."""

from __future__ import annotations

import hashlib
import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.stats import chi2

from hil.history.entry import calibration_figures, noise_figures
from hil.history.spool import _HOST, file_spooled, keep
from hil.history.store import HEAD, MIGRATIONS, History, HistoryError
from hil.outputs.result_schema import read_result
from tests.history_legacy import legacy_history
from tests.pages import CHROMIUM, clipped_columns, layout_width, needs_chromium

ROOT = Path(__file__).resolve().parents[1]


def hil(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          check=False)


def short_swing(tmp_path: Path, seed: int) -> Path:
    cfg = yaml.safe_load((ROOT / "configs" / "liu2019_sim.yaml").read_text())
    cfg["trial"].update(seed=seed, duration_s=500)  # converged by about 320 s
    path = tmp_path / f"seed{seed}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.fixture(scope="module")
def unit_a(tmp_path_factory):
    """Three trials of unit A (seeds 1-3) and one of unit B in one history; the run directories of A."""
    tmp = tmp_path_factory.mktemp("unit")
    history = str(tmp / "history.sqlite")
    runs = []
    for seed, dut in ((1, "A"), (2, "A"), (3, "A"), (4, "B")):
        out = tmp / f"run{seed}"
        done = hil("simulate", str(short_swing(tmp, seed)), "--dut", dut, "--out", str(out), "--no-figures",
                   "--history", history)
        assert done.returncode == 0, done.stderr
        if dut == "A":
            runs.append(out)
    return history, runs


def test_history_json_reports_the_units_runs_and_a_repeatability_computed_from_its_result_files(unit_a):
    history, runs = unit_a
    done = hil("history", "--dut", "A", "--json", "--history", history)
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    biases = np.array([json.loads((run / "result.json").read_text())["estimate"]["accel_bias_ug"] for run in runs])
    s = biases.std(axis=0, ddof=1)
    lo, hi = s * np.sqrt(2 / chi2.ppf(0.975, 2)), s * np.sqrt(2 / chi2.ppf(0.025, 2))
    (unit,) = doc["units"]
    assert doc["dut_serial"] == unit["dut_serial"] == "A" and unit["runs"] == 3 and len(doc["trials"]) == 3
    assert not any(unit["left_out"].values())
    np.testing.assert_allclose(unit["accel_bias_repeatability_ug"], s, rtol=1e-12)
    np.testing.assert_allclose(unit["accel_bias_repeatability_ci_ug"], np.stack([lo, hi], axis=1), rtol=1e-12)
    assert {t["out_dir"] for t in doc["trials"]} == {str(run.resolve()) for run in runs}
    assert all(read_result(run / "result.json").record.dut_serial == "A" for run in runs)


def test_history_without_a_unit_gives_each_unit_its_own_figures_never_one_pooled(unit_a):
    history, _ = unit_a
    doc = json.loads(hil("history", "--json", "--history", history).stdout)
    assert doc["dut_serial"] is None and len(doc["trials"]) == 4
    assert [(u["dut_serial"], u["runs"]) for u in doc["units"]] == [("A", 3), ("B", 1)]
    assert doc["units"][1]["accel_bias_repeatability_ug"] is None  # one run of B: no spread to take
    text = hil("history", "--history", history).stdout.splitlines()
    assert [line.split(":")[0] for line in text if not line.startswith(("started", "20"))] == ["A", "B"]
    assert "over 3 runs" in next(line for line in text if line.startswith("A:"))


@needs_chromium
def test_history_html_renders_its_parts_in_headless_chromium(unit_a, tmp_path):
    history, _ = unit_a
    assert hil("history", "--dut", "A", "--out", str(tmp_path), "--history", history).returncode == 0
    page = (tmp_path / "history.html").as_uri()
    browser = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--window-size=1400,1000"]
    dom = subprocess.run([*browser, "--dump-dom", page], capture_output=True, text=True, timeout=120).stdout
    assert "Trial history" in dom and "<h1>A</h1>" in dom and "Accelerometer bias repeatability" in dom
    assert dom.count("<tr>") >= 3 + 3 and dom.count("data:image/png;base64") >= 1
    shot = tmp_path / "shot.png"
    subprocess.run([*browser, f"--screenshot={shot}", page], capture_output=True, timeout=120)
    from matplotlib.image import imread

    pixels = imread(shot)
    assert pixels.shape[1] == 1400 and pixels[..., :3].std() > 0.05  # drawn, not blank


@needs_chromium
def test_history_html_of_every_unit_fits_1400_px_with_every_column_in_sight(unit_a, tmp_path):
    history, _ = unit_a
    assert hil("history", "--out", str(tmp_path), "--history", history).returncode == 0
    page = tmp_path / "history.html"
    assert layout_width(page, tmp_path) <= 1400
    assert clipped_columns(page, tmp_path) == []


def test_a_locked_history_and_an_unreachable_one_cost_one_warning_line_never_the_trial_the_locked_one_spools(
        tmp_path):
    locked = tmp_path / "locked.sqlite"
    sqlite3.connect(locked).close()  # an empty file: the schema is made on opening
    holder = sqlite3.connect(locked)
    holder.execute("BEGIN EXCLUSIVE")
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    try:
        for url in (str(locked), f"sqlite:///{blocker}/history.sqlite"):
            out = tmp_path / f"out-{len(url)}"
            done = hil("simulate", str(short_swing(tmp_path, 1)), "--out", str(out), "--no-figures", "--history", url)
            assert done.returncode == 0
            assert (out / "result.json").exists() and (out / "report.html").exists()
            warnings = [line for line in done.stderr.splitlines() if "warning" in line]
            assert len(warnings) == 1 and "not filed in the history" in warnings[0] and url.split("/")[-1] in warnings[0]
            assert ("kept in the spool" in warnings[0]) == (url == str(locked))  # a history that cannot be: no
    finally:
        holder.rollback()
        holder.close()
    assert History(str(locked)).trials() == []
    assert file_spooled(History(str(locked))) == 1 and len(History(str(locked)).trials()) == 1


def test_a_spooled_row_a_killed_process_had_claimed_is_filed_once_by_the_next(tmp_path):
    history = History(str(tmp_path / "h.sqlite"))
    kept = keep(history, {"kind": "swing", "dut_serial": "K", "figures": {}})
    keep(History(str(tmp_path / "other.sqlite")), {"kind": "swing", "dut_serial": "O", "figures": {}})
    dead = subprocess.Popen(["true"])  # a process that has ended, killed while it filed the row
    dead.wait()
    kept.rename(kept.with_suffix(f".{_HOST}-{dead.pid}.claim"))
    assert file_spooled(history) == 1 and file_spooled(history) == 0
    assert [t["dut_serial"] for t in history.trials()] == ["K"]
    assert len(list(kept.parent.iterdir())) == 1  # the other history's row waits for it


def test_no_history_files_nothing(tmp_path, history_in_tmp):
    out = tmp_path / "out"
    assert hil("simulate", str(short_swing(tmp_path, 1)), "--out", str(out), "--no-figures",
               "--no-history").returncode == 0
    assert not history_in_tmp.exists()


@pytest.mark.parametrize("version", [1, 2, 3])
def test_a_file_of_each_hand_written_version_is_migrated_keeping_its_rows(tmp_path, version):
    path = tmp_path / f"v{version}.sqlite"
    with legacy_history(path, version) as db:
        for serial in ("A", "B"):
            db.execute("INSERT INTO trials (kind, dut_serial, started_utc, figures) VALUES ('swing', ?, '2026', "
                       "'{\"x\": 1}')", (serial,))
    history = History(str(path))
    assert history.version() == 4
    assert [(t["id"], t["dut_serial"], t["notes"], t["replay_of"], t["figures"]) for t in history.trials()] == [
        (1, "A", None, None, {"x": 1}), (2, "B", None, None, {"x": 1})]
    history.append({"kind": "swing", "dut_serial": "C", "started_utc": "2027", "figures": {}})
    assert [t["id"] for t in history.trials()] == [1, 2, 3]
    with sqlite3.connect(path) as db:
        tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    assert tables == {"trials", "alembic_version"}  # the version is Alembic's alone


def test_head_names_the_last_migration_so_a_history_there_opens_without_alembic():
    from alembic.script import ScriptDirectory

    assert ScriptDirectory(str(MIGRATIONS)).get_current_head() == HEAD


@pytest.mark.parametrize("newer", ["schema_version", "alembic_version"])
def test_a_history_of_a_newer_schema_is_refused_naming_it(tmp_path, newer):
    path = tmp_path / "newer.sqlite"
    History(str(path)).append({"kind": "swing", "figures": {}})
    with sqlite3.connect(path) as db:
        if newer == "schema_version":
            db.execute("DROP TABLE alembic_version")
            db.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
            db.execute("INSERT INTO schema_version VALUES (99)")
        else:
            db.execute("UPDATE alembic_version SET version_num = '0099'")
    with pytest.raises(HistoryError, match=r"newer.sqlite: migrate: schema (version 99|revision 0099) is newer"):
        History(str(path)).trials()


def test_sqlalchemy_urls_reach_the_same_store(tmp_path):
    pytest.importorskip("sqlalchemy")
    history = History(f"sqlite+pysqlite:///{tmp_path / 'h.sqlite'}")
    history.append({"kind": "swing", "dut_serial": "A", "started_utc": "2026-01-01", "figures": {"a": [1.0]}})
    assert [t["figures"] for t in History(str(tmp_path / "h.sqlite")).trials("A")] == [{"a": [1.0]}]


def test_calibration_and_noise_rows_hold_every_term_by_block_and_key():
    calibration = {"accel": {"bias_ug": [1.0, 2.0, 3.0]}, "gyro": {"bias_dph": [0.1, None, 0.3]},
                   "sigma": {"accel": {"bias_ug": [0.5, 0.5, 0.5]}, "gyro": {"bias_dph": [0.01, None, 0.01]}},
                   "turntable": {"zero_offset_arcsec": [1.0, 2.0, 3.0]}}
    assert calibration_figures(calibration) == {
        "accel.bias_ug": [1.0, 2.0, 3.0], "accel.bias_ug.sigma": [0.5, 0.5, 0.5], "gyro.bias_dph": [0.1, None, 0.3],
        "gyro.bias_dph.sigma": [0.01, None, 0.01], "turntable.zero_offset_arcsec": [1.0, 2.0, 3.0]}
    noise = {"gyro": {"arw_deg_per_sqrt_h": [1, 2, 3]}, "accel": {"vrw_m_per_s_per_sqrt_h": [4, 5, 6]}, "tau_s": []}
    assert noise_figures(noise) == {"gyro.arw_deg_per_sqrt_h": [1, 2, 3], "accel.vrw_m_per_s_per_sqrt_h": [4, 5, 6]}


def test_a_noise_run_carries_its_record_and_is_filed_with_its_terms(tmp_path):
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["trial"].update(duration_s=400, rate_hz=50, name="static-noise")
    cfg["turntable"]["motion"] = {"kind": "static"}
    cfg["output"] = {}
    cfg["record"] = {"dut_part": "KVH-1750"}
    config = tmp_path / "static.yaml"
    config.write_text(yaml.safe_dump(cfg))
    history = str(tmp_path / "h.sqlite")
    done = hil("noise", str(config), "--out", str(tmp_path / "n"), "--no-figures", "--dut", "N7", "--history", history)
    assert done.returncode == 0, done.stderr
    noise = json.loads((tmp_path / "n" / "noise.json").read_text())
    assert noise["record"]["dut_serial"] == "N7" and noise["record"]["dut_part"] == "KVH-1750"
    assert noise["record"]["config_sha256"] == hashlib.sha256(config.read_bytes()).hexdigest()
    (row,) = History(history).trials("N7")
    assert row["kind"] == "noise" and row["dut_part"] == "KVH-1750"
    assert row["figures"]["gyro.arw_deg_per_sqrt_h"] == noise["gyro"]["arw_deg_per_sqrt_h"]
