"""One output directory, one trial: ``--out`` naming a directory that holds outputs is refused unless
``--overwrite`` (which leaves none of the replaced trial's files, and unpoints its history row), and a lock keeps a
second command out while one writes there, a lock its holder's death releases."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from hil.cli import main
from hil.outputs.output_dir import TRIAL_OUTPUTS, claimed

ROOT = Path(__file__).resolve().parents[1]
SIMULATE = ["simulate", str(ROOT / "configs" / "emulated_swing.yaml"), "--no-figures"]


@pytest.fixture
def short(tmp_path) -> Path:
    """emulated_swing.yaml, 20 s long, without its limits on the estimate (too short to meet them)."""
    import yaml

    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["trial"]["duration_s"] = 20
    cfg.get("output", {}).pop("limits", None)
    path = tmp_path / "short.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _rows(history: Path) -> list[tuple]:
    with sqlite3.connect(history) as db:
        return db.execute("SELECT id, out_dir FROM trials ORDER BY id").fetchall()


def test_a_directory_holding_a_trials_outputs_is_refused_unless_overwrite(tmp_path, short, capsys):
    out, history = tmp_path / "out", tmp_path / "history.sqlite"
    args = ["simulate", str(short), "--no-figures", "--out", str(out), "--history", str(history)]
    assert main(args) == 0
    first = (out / "result.json").read_bytes()
    (out / "emulator.json").write_text("{}")  # as a live trial leaves it: no simulation writes one
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--out {out}: holds the outputs of a trial" in err and "--overwrite" in err
    assert (out / "result.json").read_bytes() == first and len(_rows(history)) == 1
    assert main([*args, "--overwrite"]) == 0
    assert not (out / "emulator.json").exists() and not (out / ".hil.lock").exists()
    assert _rows(history) == [(1, None), (2, str(out.resolve()))]  # the replaced trial's row points nowhere


def test_a_second_command_is_kept_out_while_one_writes_there(tmp_path, short, capsys):
    out = tmp_path / "out"
    with claimed(out, TRIAL_OUTPUTS):
        assert main(["simulate", str(short), "--no-figures", "--no-history", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"another hil command (pid {os.getpid()}) is writing its outputs" in err
        assert sorted(p.name for p in out.iterdir()) == [".hil.lock"]
    assert not out.exists()  # made for the claim, left as found
    assert main(["simulate", str(short), "--no-figures", "--no-history", "--out", str(out)]) == 0


def test_the_lock_of_a_killed_command_does_not_block_the_next(tmp_path, short):
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from pathlib import Path; "
                               "from hil.outputs.output_dir import TRIAL_OUTPUTS, claimed\n"
                               f"with claimed(Path({str(out)!r}), TRIAL_OUTPUTS):\n"
                               "    print('held', flush=True); time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline() == "held\n"
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    holder.stdout.close()
    assert (out / ".hil.lock").exists()  # left behind, unlocked
    assert main(["simulate", str(short), "--no-figures", "--no-history", "--out", str(out)]) == 0


def test_two_trials_at_once_into_one_directory_write_and_file_one(tmp_path, short):
    out, history = tmp_path / "out", tmp_path / "history.sqlite"
    command = [str(Path(sys.executable).parent / "hil"), "simulate", str(short), "--no-figures", "--out", str(out),
               "--history", str(history)]
    procs = [subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    done = [(p.wait(timeout=120), *p.communicate()) for p in procs]
    assert sorted(code for code, _, _ in done) == [0, 2], done
    refused = next(err for code, _, err in done if code == 2)
    assert refused.count("\n") == 1 and f"--out {out}: " in refused
    assert sum(f"outputs in {out}" in text for _, text, _ in done) == 1
    assert _rows(history) == [(1, str(out.resolve()))]
    assert json.loads((out / "result.json").read_text())["verdict"] == "PASS"


def test_a_second_replay_into_its_default_directory_is_refused(tmp_path, short, capsys):
    run = tmp_path / "run"
    fast = ["--viewer", "none", "--no-figures", "--no-history"]
    assert main(["run", str(short), "--speed", "max", "--quiet", "--out", str(run), *fast]) == 0
    assert main(["replay", str(run), *fast]) == 0
    capsys.readouterr()
    assert main(["replay", str(run), *fast]) == 2
    assert f"--out {run / 'replay'}: holds the outputs of a trial" in capsys.readouterr().err
    assert main(["replay", str(run), *fast, "--overwrite"]) == 0
    capsys.readouterr()
    assert main(["replay", str(run), *fast, "--out", str(run), "--overwrite"]) == 2  # it would take the recording
    assert "the recording's own directory" in capsys.readouterr().err and (run / "recording.mcap").exists()


def test_a_trial_run_again_from_its_own_config_copy_replaces_all_but_that(tmp_path, short):
    out = tmp_path / "out"
    assert main(["simulate", str(short), "--no-figures", "--no-history", "--out", str(out)]) == 0
    again = ["simulate", str(out / "config.yaml"), "--no-figures", "--no-history", "--out", str(out)]
    assert main(again) == 2
    assert main([*again, "--overwrite"]) == 0
    assert (out / "config.yaml").read_text() == short.read_text()


def test_replaced_outputs_are_forgotten_without_sqlalchemy_in_a_sqlite_history_of_the_last_revision(tmp_path):
    """:func:`hil.history.location.forgotten`: a SQLite file not there, or one at the last revision, needs no
    SQLAlchemy; anything else is left to the store, which migrates, updates and words its failures as before."""
    from hil.history.location import forgotten
    from hil.history.store import History
    from tests.history_legacy import legacy_history

    out, other, history = str(tmp_path / "out"), str(tmp_path / "other"), tmp_path / "history.sqlite"
    assert forgotten(str(history), out) and not history.exists()  # not made for nothing
    for out_dir in (out, other, out):
        History(str(history)).append({"kind": "swing", "out_dir": out_dir, "figures": {}})
    assert forgotten(str(history), out)
    assert _rows(history) == [(1, None), (2, other), (3, None)]
    assert not forgotten(f"sqlite:///{history}", out)  # a URL: the store's
    legacy = legacy_history(tmp_path / "legacy.sqlite", 3)
    legacy.commit()
    legacy.close()
    assert not forgotten(str(tmp_path / "legacy.sqlite"), out)  # an older schema: migrated by the store first
    (tmp_path / "garbage.sqlite").write_text("not a database")
    assert not forgotten(str(tmp_path / "garbage.sqlite"), out)  # its error is the store's to word
    with sqlite3.connect(history, isolation_level=None) as writer:
        writer.execute("BEGIN IMMEDIATE")  # another writer holds the lock: the store waits for it, as before
        assert not forgotten(str(history), other)
        writer.execute("ROLLBACK")
    assert _rows(history)[1] == (2, other)
