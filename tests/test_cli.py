import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emulators.simulation import Simulation
from hil.cli import main
from hil.units import DEG
from tests.helpers import PAPER_ERRORS, make_config


def write_config(path, **kwargs):
    cfg = make_config(**kwargs)
    import yaml

    path.write_text(yaml.safe_dump(cfg.model_dump(mode="json", exclude_none=True)))
    return cfg


def test_simulate_writes_result_series_and_figures(tmp_path):
    write_config(tmp_path / "c.yaml", duration=60, errors=PAPER_ERRORS)
    assert main(["simulate", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "out")]) == 0
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["trial"]["samples"] == 6000
    assert result["estimate"]["observable"] is True
    assert result["estimate"]["gram_rank"] == 12
    assert result["truth"]["accel_bias_ug"] == [60.0, 150.0, 260.0]
    bias, sigma = (np.array(result["estimate"][k]) for k in ("accel_bias_ug", "accel_bias_sigma_ug"))
    assert np.all(np.abs(bias - PAPER_ERRORS["accel_bias_ug"]) < 4 * sigma)  # what the files say: the estimate
    assert set(result["alignment_deg"]) == {"method1", "method2", "theoretical"}
    assert abs(result["alignment_deg"]["method2"]["pitch"]) < 0.01  # the paper's method 2: near the table
    with open(tmp_path / "out" / "series.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    last = rows[-1]
    assert float(last["t_s"]) == pytest.approx(60.0) and [float(last[f"bias_{a}_ug"]) for a in "xyz"] == \
        pytest.approx(bias.tolist(), rel=1e-9)  # the series ends at the result's estimate
    assert (tmp_path / "out" / "config.yaml").read_text() == (tmp_path / "c.yaml").read_text()
    report = (tmp_path / "out" / "report.html").read_text()
    assert "<h1>" in report and f"{bias[2]:.4g}"[:4] in report
    for name in ("bias.png", "alignment.png", "observability.png"):
        assert (tmp_path / "out" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("flags", [[], ["--no-figures"]])
def test_simulate_draws_each_figure_once_in_the_figure_process(tmp_path, monkeypatch, flags):
    import hil.outputs.figure_process
    import hil.outputs.figures

    handed, here = [], []
    draw = hil.outputs.figure_process.FigureProcess.draw
    monkeypatch.setattr(hil.outputs.figure_process.FigureProcess, "draw",
                        lambda self, out, *args: handed.append(out) or draw(self, out, *args))
    monkeypatch.setattr(hil.outputs.figure_process, "write_figures", lambda out, *args: here.append(out))
    write_config(tmp_path / "c.yaml", duration=60, errors=PAPER_ERRORS)
    assert main(["simulate", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "out"), *flags]) == 0
    assert len(handed) == 1 and here == []  # drawn once, by the child
    assert all((tmp_path / "out" / name).exists() != bool(flags) for name in hil.outputs.figures.FIGURES)
    page = (tmp_path / "out" / "report.html").read_text()
    assert len(re.findall(r"src='data:image/png;base64,", page)) == len(hil.outputs.figures.FIGURES)


def test_the_parser_imports_neither_rerun_nor_matplotlib():
    code = ("import sys; from hil.cli import build_parser; build_parser(); "
            "print('rerun' in sys.modules, 'matplotlib' in sys.modules)")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_estimate_on_exported_csv_matches_simulate(tmp_path):
    cfg = write_config(tmp_path / "c.yaml", duration=60, errors=PAPER_ERRORS)
    sim = Simulation.from_config(cfg)
    with open(tmp_path / "data.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_s", "dtheta_x_rad", "dtheta_y_rad", "dtheta_z_rad", "dv_x_mps", "dv_y_mps", "dv_z_mps",
                    "outer_deg", "middle_deg", "inner_deg", "ignored"])  # fmt: skip
        for b in sim.batches():
            for k in range(len(b)):
                values = [b.t[k], *b.dtheta[k], *b.dv[k], *(b.angles[k] / DEG)]
                w.writerow([repr(float(v)) for v in values] + ["x"])
    assert main(["simulate", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "sim"), "--no-figures"]) == 0
    assert main(["estimate", str(tmp_path / "data.csv"), "--config", str(tmp_path / "c.yaml"),
                 "--out", str(tmp_path / "est"), "--no-figures"]) == 0  # fmt: skip
    a = json.loads((tmp_path / "sim" / "result.json").read_text())["estimate"]
    b = json.loads((tmp_path / "est" / "result.json").read_text())["estimate"]
    np.testing.assert_allclose(a["accel_bias_ug"], b["accel_bias_ug"], atol=1e-6)


def _run(*args):
    return subprocess.run([sys.executable, "-m", "hil.cli", *args], capture_output=True, text=True)


def test_bad_config_is_one_clear_line_and_exit_2(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("trial: {duration_s: 10}\nsite: {latitude_deg: 32}\nimu: {errors: {accel_bias_ug: [1, 2]}}\n")
    proc = _run("simulate", str(path), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2
    assert "imu.errors.accel_bias_ug: expected 3 numbers, got 2" in proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "content, reason",
    [
        ("t_s,dtheta_x_rad\n1,2\n", "lacks required column"),
        ("t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps\n1,0,0,0,0,0,0\n0.5,0,0,0,0,0,0\n", ":3: t_s"),
        ("t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps\n1,0,0,zero,0,0,0\n", ":2: expected numbers"),
    ],
)
def test_bad_csv_is_one_clear_line_and_exit_2(tmp_path, content, reason):
    write_config(tmp_path / "c.yaml")
    (tmp_path / "d.csv").write_text(content)
    proc = _run("estimate", str(tmp_path / "d.csv"), "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2
    assert reason in proc.stderr and "Traceback" not in proc.stderr


def test_decode_prints_counters_as_json_on_the_last_line(tmp_path, capsys):
    published = bytes.fromhex("FE81FF55 37A96A6E 38586C1F B75BF862 BF803E78 BB650D28 3B0A37AC 77 3D 0028 4BFA34D8")
    (tmp_path / "cap.bin").write_bytes(b"\x00\x13garbage" + published + published[:20])
    assert main(["decode", "kvh1750", str(tmp_path / "cap.bin"), "--out", str(tmp_path / "out.csv")]) == 0
    counters = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert counters["frames"] == 1
    assert counters["skipped_bytes"] >= 9
    rows = list(csv.reader(open(tmp_path / "out.csv")))
    assert rows[0][0] == "sync_index" and len(rows) == 2


def test_emulate_writes_ports_and_exits_cleanly_on_sigterm(tmp_path):
    import signal
    import time

    write_config(tmp_path / "c.yaml", duration=600)
    ports = tmp_path / "ports.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "hil.cli", "emulate", str(tmp_path / "c.yaml"), "--ports-file", str(ports)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 20
    while not ports.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    names = json.loads(ports.read_text())
    assert names["imu"].startswith("/dev/pts/") and names["turntable_data"].startswith("/dev/pts/")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=10) == 0
    assert not ports.exists()


def test_emulate_rejects_a_bad_speed(tmp_path):
    write_config(tmp_path / "c.yaml")
    proc = _run("emulate", str(tmp_path / "c.yaml"), "--speed", "fast")
    assert proc.returncode == 2 and "--speed" in proc.stderr


def test_report_rebuilds_the_html_and_names_a_missing_directory(tmp_path, capsys):
    write_config(tmp_path / "c.yaml", duration=30, errors=PAPER_ERRORS)
    out = tmp_path / "out"
    assert main(["simulate", str(tmp_path / "c.yaml"), "--out", str(out), "--no-figures"]) == 0
    (out / "report.html").unlink()
    (out / "junit.xml").unlink()
    assert main(["report", str(out)]) == 0
    assert "<html" in (out / "report.html").read_text().lower()
    assert (out / "junit.xml").read_text().startswith("<?xml")
    assert main(["report", str(tmp_path / "nothing")]) == 2
    assert "nothing" in capsys.readouterr().err
    result = json.loads((out / "result.json").read_text())
    result["estimate"]["accel_bias_sigma_ug"] = [str(v) for v in result["estimate"]["accel_bias_sigma_ug"]]
    (out / "result.json").write_text(json.dumps(result))
    assert main(["report", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "estimate.accel_bias_sigma_ug.0: input should be a valid number" in err


@pytest.fixture
def bad_inputs(tmp_path):
    """Files that ``hil decode`` and ``hil replay`` must refuse."""
    (tmp_path / "cap.bin").write_bytes(bytes(64))
    (tmp_path / "empty.bin").write_bytes(b"")
    (tmp_path / "cap.asc").write_text("date Mon Jan 1 00:00:00 2024\nbase hex timestamps absolute\n")
    (tmp_path / "cap.blf").write_bytes(b"not a BLF file")
    (tmp_path / "bad.dbc").write_text("not a DBC\n")
    (tmp_path / "other.dbc").write_text('VERSION ""\nBO_ 100 Other: 8 Vector__XXX\n'
                                        ' SG_ Speed : 0|8@1+ (1,0) [0|255] "km/h" Vector__XXX\n')  # fmt: skip
    (tmp_path / "text.mcap").write_text("hello, not a recording\n")
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "run").mkdir()
    return tmp_path


@pytest.mark.parametrize(
    "args, named, reason",
    [
        (["decode", "kvh1750", "{d}/missing.bin"], "missing.bin", "no such file"),
        (["decode", "kvh1750", "{d}/run"], "run", "a directory, not a capture"),
        (["decode", "kvh1750", "{d}/empty.bin"], "empty.bin", "empty file, nothing to decode"),
        (["decode", "nmea", "{d}/cap.bin"], "protocol: 'nmea'", "unknown; protocols: acl, can-dbc"),
        (["decode", "acl", "{d}/cap.bin"], "protocol 'acl'", "a command protocol, no data frames"),
        (["decode", "can-dbc", "{d}/cap.bin"], "cap.bin", "a can-dbc capture must be a python-can log (.blf"),
        (["decode", "can-dbc", "{d}/cap.blf"], "cap.blf", "not a readable .blf CAN log"),
        (["decode", "can-dbc", "{d}/cap.asc", "--dbc", "{d}/missing.dbc"], "missing.dbc", "cannot read: No such file"),
        (["decode", "can-dbc", "{d}/cap.asc", "--dbc", "{d}/bad.dbc"], "bad.dbc", "not a usable DBC"),
        (["decode", "can-dbc", "{d}/cap.asc", "--dbc", "{d}/other.dbc"], "other.dbc", "none of the shipped signal"),
        (["decode", "kvh1750", "{d}/cap.bin", "--dbc", "{d}/other.dbc"], "--dbc", "only for a CAN protocol"),
        (["decode", "kvh1750", "{d}/cap.bin", "--out", "{d}/no/out.csv"], "out.csv", "No such file"),
        (["decode", "auto", "{d}/cap.bin"], "cap.bin", "no run of kvh1750, tts1, xsens-mtdata2 frames in its first 64"),
        (["decode", "auto", "{d}/cap.asc"], "cap.asc", "a CAN log needs can-dbc (and --dbc)"),
        (["decode", "auto", "{d}/empty.bin"], "empty.bin", "empty file, nothing to decode"),
        (["replay", "{d}/text.mcap"], "text.mcap", "not a turntable-hil recording (not a valid MCAP file"),
        (["replay", "{d}/empty.mcap"], "empty.mcap", "the file ends before the trial metadata"),
        (["replay", "{d}/run"], "recording.mcap", "cannot read: No such file"),
    ],
)
def test_unusable_capture_or_recording_is_one_line_and_exit_2(bad_inputs, capsys, args, named, reason):
    assert main([a.format(d=bad_inputs) for a in args]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("hil: error: ") and captured.err.count("\n") == 1
    assert named in captured.err and reason in captured.err
    assert captured.out == ""


def test_simulate_refuses_a_config_that_reads_devices_in_one_line(tmp_path, capsys):
    lab = Path(__file__).resolve().parents[1] / "configs" / "lab_swing.yaml"
    assert main(["simulate", str(lab), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lab_swing.yaml: imu.source: serial: hil simulate emulates the devices" in err
    assert not (tmp_path / "o").exists()


def test_campaign_help_lists_every_kind(capsys):
    from hil.campaign.kinds import KINDS

    with pytest.raises(SystemExit):
        main(["campaign", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "kind: " + "|".join(KINDS) in text


@pytest.mark.parametrize("args, named", [
    (["run", "--duration", "-5"], "--duration"),
    (["run", "--duration", "0"], "--duration"),
    (["run", "--duration", "inf"], "--duration"),
    (["emulate", "--duration", "-3"], "--duration"),
    (["noise", "configs/noise_static.yaml", "--duration", "nan"], "--duration"),
    (["decode", "kvh1750", "capture.bin", "--rate", "-5"], "--rate"),
])
def test_a_duration_or_rate_that_cannot_be_is_one_line_and_exit_2(tmp_path, capsys, args, named):
    with pytest.raises(SystemExit) as stopped:
        main([*args, "--out", str(tmp_path / "out")] if args[0] != "emulate" else args)
    err = capsys.readouterr().err
    assert stopped.value.code == 2 and err.count("\n") == 1 and err.startswith(f"hil: error: argument {named}: ")
    assert not (tmp_path / "out").exists()


def test_noise_of_a_simulated_config_lasts_its_duration(tmp_path):
    out = tmp_path / "noise"
    assert main(["noise", "configs/noise_static.yaml", "--duration", "120", "--out", str(out), "--no-figures",
                 "--no-history"]) == 0
    doc = json.loads((out / "noise.json").read_text())
    assert doc["samples"] == 120 * 100 and doc["duration_s"] == pytest.approx(120.0, abs=0.01)
