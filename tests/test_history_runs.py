"""What the history counts as a unit's runs (docs/history.md, "Repeatability"): completed, observable,
converged swing trials of one unit, never a replay of one; what it leaves out, and why; the dates and files
``hil history`` refuses; a replay keeping its recorded trial's record."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from hil.cli import main
from hil.history.store import History
from tests.history_legacy import legacy_history

ROOT = Path(__file__).resolve().parents[1]
GOOD = ([10.0, 20.0, 30.0], [12.0, 19.0, 33.0], [11.0, 23.0, 29.0])  # the bias of three sound runs (ug)


def hil(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          check=False)


@pytest.fixture
def history(capsys):
    """``hil history ARGS`` in this process: (exit code, stdout, stderr)."""

    def run(*args: str) -> tuple[int, str, str]:
        code = main(["history", *args])
        out, err = capsys.readouterr()
        return code, out, err

    return run


def swing(dut: str | None, bias: list[float] | None, started: str, ended: str = "completed",
          converged_at_s: float | None = 150.0, replay_of: str | None = None, verdict: str = "PASS") -> dict:
    """A swing row as the CLI files it."""
    return {"kind": "swing", "name": "swing", "ended": ended, "verdict": verdict, "dut_serial": dut,
            "started_utc": started, "replay_of": replay_of,
            "figures": {"accel_bias_ug": bias, "accel_bias_sigma_ug": None if bias is None else [1.0, 1.0, 1.0],
                        "observable": bias is not None, "converged_at_s": converged_at_s}}


@pytest.fixture
def unit_with_misleading_runs(tmp_path) -> str:
    """Unit A: three sound runs, a 60 s run that never converged (and FAILed), an interrupted one, a static one
    (bias unobservable) and a replay of the first; unit B: one run; a run without a serial."""
    history = str(tmp_path / "h.sqlite")
    rows = [swing("A", bias, f"2026-12-0{day}T10:00:00+00:00") for day, bias in enumerate(GOOD, start=1)]
    rows += [swing("A", [900.0, -400.0, 80.0], "2026-12-04T10:00:00+00:00", converged_at_s=None, verdict="FAIL"),
             swing("A", [500.0, 500.0, 500.0], "2026-12-04T11:00:00+00:00", ended="interrupted: SIGINT",
                   verdict="INTERRUPTED"),
             swing("A", None, "2026-12-04T12:00:00+00:00", converged_at_s=None, verdict="FAIL"),
             swing("A", [10.5, 20.5, 30.5], "2026-12-05T10:00:00+00:00", replay_of="/runs/a1"),
             swing("B", [-5.0, 0.0, 5.0], "2026-12-02T09:00:00+00:00"),
             swing(None, [400.0, 0.0, 0.0], "2026-12-02T08:00:00+00:00")]
    for row in rows:
        History(history).append(row)
    return history


def test_repeatability_takes_only_completed_observable_converged_trials_and_says_what_it_left_out(
        unit_with_misleading_runs, history):
    code, out, err = history("--dut", "A", "--json", "--history", unit_with_misleading_runs)
    assert code == 0, err
    (unit,) = json.loads(out)["units"]
    assert unit["runs"] == 3
    assert unit["left_out"] == {"no_serial": 0, "replay": 1, "not_completed": 1, "not_observable": 1,
                                "not_converged": 1}
    np.testing.assert_allclose(unit["accel_bias_repeatability_ug"], np.std(GOOD, axis=0, ddof=1), rtol=1e-12)
    np.testing.assert_allclose(unit["accel_bias_mean_ug"], np.mean(GOOD, axis=0), rtol=1e-12)
    text = history("--dut", "A", "--history", unit_with_misleading_runs)[1].splitlines()
    assert text[-1].startswith("A: bias repeatability over 3 runs")
    assert text[-1].endswith("left out: 1 replays of a trial, 1 not completed, 1 bias not observable, 1 not converged")


def test_history_of_every_unit_gives_one_line_per_unit_and_pools_none(unit_with_misleading_runs, history):
    doc = json.loads(history("--json", "--history", unit_with_misleading_runs)[1])
    assert [(u["dut_serial"], u["runs"]) for u in doc["units"]] == [("A", 3), ("B", 1), (None, 0)]
    assert doc["units"][2]["left_out"]["no_serial"] == 1
    lines = history("--history", unit_with_misleading_runs)[1].splitlines()
    assert [line.split(":")[0] for line in lines[-3:]] == ["A", "B", "(no serial)"]
    assert len(lines) == 1 + 9 + 3  # the header, the rows, one line per unit
    interrupted = next(line for line in lines if line.startswith("2026-12-04T11:00"))
    assert interrupted.split()[1:5] == ["swing", "A", "interrupted", "INTERRUPTED"]


@pytest.mark.parametrize("since", ["garbage", "2026-13-45", "2026-12-04T25:00"])
def test_a_since_that_is_not_a_date_exits_2_in_one_line_naming_it(unit_with_misleading_runs, history, since):
    code, out, err = history("--since", since, "--history", unit_with_misleading_runs)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and f"--since {since}:" in err


def test_since_keeps_the_trials_started_at_or_after_it_in_utc(unit_with_misleading_runs, history):
    def started(since: str) -> list[str]:
        out = history("--dut", "A", "--json", "--since", since, "--history", unit_with_misleading_runs)[1]
        return [t["started_utc"][:16] for t in json.loads(out)["trials"]]

    assert started("2026-12-04T11:00") == ["2026-12-04T11:00", "2026-12-04T12:00", "2026-12-05T10:00"]
    assert started("2026-12-04T13:00+02:00") == started("2026-12-04T11:00")  # 11:00 UTC


def test_reading_a_history_that_does_not_exist_exits_2_in_one_line_and_creates_nothing(tmp_path, history):
    for path in (tmp_path / "absent.sqlite", tmp_path / "no-such-dir" / "h.sqlite"):
        code, out, err = history("--history", str(path))
        assert code == 2 and out == ""
        assert err.count("\n") == 1 and str(path) in err and "no trial history there" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_filing_in_a_directory_that_does_not_exist_warns_and_makes_no_directory(tmp_path):
    config = tmp_path / "short.yaml"
    cfg = yaml.safe_load((ROOT / "configs" / "liu2019_sim.yaml").read_text())
    cfg["trial"]["duration_s"] = 60
    config.write_text(yaml.safe_dump(cfg))
    url = str(tmp_path / "no-such-dir" / "h.sqlite")
    done = hil("simulate", str(config), "--out", str(tmp_path / "out"), "--no-figures", "--history", url)
    assert done.returncode == 0 and (tmp_path / "out" / "result.json").exists()
    (warning,) = [line for line in done.stderr.splitlines() if "warning" in line]
    assert "not filed in the history" in warning and "no such directory" in warning
    assert not (tmp_path / "no-such-dir").exists()


def test_rows_of_trials_that_did_not_complete_filed_as_pass_or_fail_are_migrated_to_how_they_ended(tmp_path):
    path = tmp_path / "v2.sqlite"
    with legacy_history(path, 2) as db:
        for ended, verdict in (("interrupted: SIGINT", "PASS"), ("early: devices lost", "FAIL"),
                               ("completed", "FAIL"), ("completed", None)):
            db.execute("INSERT INTO trials (kind, ended, verdict, figures) VALUES ('swing', ?, ?, '{}')",
                       (ended, verdict))
    assert [t["verdict"] for t in History(str(path)).trials()] == ["INTERRUPTED", "ENDED EARLY", "FAIL", None]


@pytest.fixture(scope="module")
def recorded_trial(tmp_path_factory) -> tuple[Path, str]:
    """A 20 s live trial of unit U7 (emulated devices, --speed max), recorded and filed; its run directory and
    history."""
    tmp = tmp_path_factory.mktemp("recorded")
    history, run = str(tmp / "h.sqlite"), tmp / "run"
    done = hil("run", "configs/emulated_swing.yaml", "--duration", "20", "--speed", "max", "--quiet", "--viewer",
               "none", "--no-figures", "--dut", "U7", "--operator", "ann", "--station", "bench-2", "--out", str(run),
               "--history", history)
    assert done.returncode in (0, 3), done.stderr
    return run, history


def test_a_replay_keeps_its_trials_record_and_is_filed_as_its_replay_never_as_another_run(recorded_trial, tmp_path,
                                                                                         history):
    run, url = recorded_trial
    done = hil("replay", str(run), "--out", str(tmp_path / "replay"), "--viewer", "none", "--no-figures",
               "--history", url)
    assert done.returncode in (0, 3), done.stderr
    record = json.loads((tmp_path / "replay" / "result.json").read_text())["record"]
    assert (record["dut_serial"], record["operator"], record["station"]) == ("U7", "ann", "bench-2")
    trial, replay = History(url).trials("U7")
    assert (trial["replay_of"], replay["replay_of"]) == (None, str(run.resolve()))
    (unit,) = json.loads(history("--dut", "U7", "--json", "--history", url)[1])["units"]
    assert unit["left_out"]["replay"] == 1 and unit["runs"] + sum(unit["left_out"].values()) == 2
    table = history("--dut", "U7", "--history", url)[1].splitlines()
    assert [line.split()[1] for line in table[1:3]] == ["swing", "replay"]


def test_noise_of_a_recording_carries_its_trials_unit(recorded_trial, tmp_path):
    run, _ = recorded_trial
    done = hil("noise", str(run), "--out", str(tmp_path / "n"), "--no-figures", "--no-history")
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "n" / "noise.json").read_text())["record"]
    assert (record["dut_serial"], record["operator"], record["station"]) == ("U7", "ann", "bench-2")
