"""Several units on one table, live (docs/units.md): ``hil emulate`` of a units config streams a port per unit,
and ``hil run`` pairs, estimates, records and ends each unit on its own against the one table stream."""

from __future__ import annotations

import copy
import json
import os
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from emulators.bench import device_streams
from emulators.process import EmulatorRun, spawn_emulator, stop_emulator
from hil.cli import main
from hil.config import parse_config
from hil.outputs.result_schema import UnitsResult
from tests.lab_form import SWING, Emulator

# a lab-form test runs real-time devices in their own process: opt-in, on a host not also running the suite
lab_tests = pytest.mark.skipif(not os.environ.get("HIL_LAB_TESTS"), reason="lab form: set HIL_LAB_TESTS=1")
TRUTHS = {"kvh-a": [60.0, 150.0, 260.0], "kvh-b": [-120.0, 40.0, 310.0], "xsens": [200.0, -90.0, 500.0]}


def units_config(duration_s: float = 20.0, **faults: dict) -> dict:
    """Three emulated units (two KVH 1750, mounted apart, and an Xsens upside down) on one swinging table; ``faults``
    by unit name."""
    units = [{"name": name, "record": {"dut_serial": name.upper()}, "mounting_deg": mounting,
              "imu": {"protocol": protocol, "errors": {"accel_bias_ug": TRUTHS[name], "accel_noise_ug": [50] * 3,
                                                       "gyro_bias_dph": [0.01] * 3, "gyro_noise_dph": [0.01] * 3},
                      **({"faults": faults[name]} if name in faults else {})}}
             for name, mounting, protocol in (("kvh-a", [0, 0, 0], "kvh1750"), ("kvh-b", [90, 0, 0], "kvh1750"),
                                              ("xsens", [0, 180, 0], "xsens-mtdata2"))]
    return {"trial": {"name": "units-live", "duration_s": duration_s, "rate_hz": 200.0, "seed": 5},
            "site": {"latitude_deg": 32.0, "longitude_deg": 118.0, "height_m": 10.0},
            "turntable": {"latch_delay_us": 50, "motion": {"kind": "swing", "axes": SWING}},
            "units": units, "estimator": {"solve_rate_hz": 1}, "output": {"limits": {}}}


def write(tmp: Path, cfg: dict, name: str = "units.yaml") -> Path:
    path = tmp / name
    path.write_text(yaml.safe_dump(cfg))
    return path


def unit_results(out: Path) -> dict[str, dict]:
    return {name: json.loads((out / "units" / name / "result.json").read_text()) for name in TRUTHS}


def within(doc: dict, truth: list[float], sigmas: float = 5.0) -> bool:
    estimate = doc["estimate"]
    return all(abs(b - t) <= sigmas * s for b, t, s in zip(estimate["accel_bias_ug"], truth,
                                                          estimate["accel_bias_sigma_ug"], strict=True))


def test_each_emulated_unit_streams_what_its_own_one_unit_config_streams_alone():
    """Every IMU senses the one table motion through its own mounting, with its own errors, noise and counter
    start: its frames are those of its one-unit config (OUT/units/<name>/config.yaml) emulated alone."""
    cfg = parse_config(units_config(), units=True)
    servo, streams = device_streams(cfg, 2.0)
    assert list(streams) == ["imu.kvh-a", "imu.kvh-b", "imu.xsens", "turntable_data"]
    frames = {name: [stream.pop(servo).payload for _ in range(50)] for name, stream in streams.items()}
    for name, unit in cfg.unit_configs().items():
        alone_servo, alone = device_streams(unit, 2.0)
        assert [alone["imu"].pop(alone_servo).payload for _ in range(50)] == frames[f"imu.{name}"]
    assert len({tuple(f) for f in frames.values()}) == 4
    counters = {name: int(stream.source.clock.counters(np.arange(1, 2))[0]) for name, stream in streams.items()}
    assert len(set(counters.values())) == 4  # each device counts from its own start


def test_the_table_counts_the_pulse_train_of_units_faster_than_its_latches():
    """Units at 1 kHz on a table latching at 200 Hz: the table's counter steps by 5 pulses a frame, as each unit's
    one-unit config expects of it."""
    data = units_config()
    for unit in data["units"]:
        unit["imu"]["rate_hz"] = 1000.0
    cfg = parse_config(data, units=True)
    servo, streams = device_streams(cfg, 1.0)
    table = streams["turntable_data"].source.clock
    steps = np.diff(table.counters(np.arange(1, 12)))
    assert set(steps) == {5} and {u.table_counts_per_frame for u in cfg.unit_configs().values()} == {5}


def test_a_units_trial_runs_live_each_unit_on_its_own_and_replays_bit_for_bit(tmp_path):
    out = tmp_path / "run"
    code = main(["run", str(write(tmp_path, units_config())), "--speed", "max", "--out", str(out), "--no-history",
                 "--no-figures", "--quiet"])
    index = json.loads((out / "result.json").read_text())
    assert code == 0 and index["ended"] == "completed", index
    live = unit_results(out)
    for name, doc in live.items():
        assert doc["ended"] == "completed" and doc["record"]["dut_serial"] == name.upper()
        assert doc["streams"]["sync"]["paired_by"] == "motion"
        assert within(doc, TRUTHS[name]), (name, doc["estimate"]["accel_bias_ug"])
        assert (out / "units" / name / "recording.mcap").stat().st_size > 0
    again = tmp_path / "again"
    assert main(["replay", str(out), "--out", str(again), "--no-history", "--no-figures"]) == 0
    replayed = unit_results(again)
    for name in TRUTHS:
        assert {k: v for k, v in replayed[name].items() if k != "record"} == \
            {k: v for k, v in live[name].items() if k != "record"}


def test_a_unit_whose_imu_goes_silent_ends_early_on_its_own_and_the_others_complete(tmp_path):
    cfg = units_config(30.0, **{"kvh-b": {"power_cycle_at_s": 8.0, "power_cycle_s": 1000.0}})
    cfg["output"]["outage_limit_s"] = 3.0
    out = tmp_path / "run"
    code = main(["run", str(write(tmp_path, cfg)), "--speed", "max", "--out", str(out), "--no-history",
                 "--no-figures", "--quiet"])
    docs = unit_results(out)
    assert code == 1
    # on the host's clock its IMU is silent for 3 s, or (at --speed max) the devices' run ends first
    assert docs["kvh-b"]["ended"] in ("early: the emulated devices stopped at 8.0 s of 30.0 s",) or \
        docs["kvh-b"]["ended"].startswith("early: no data from the imu (")
    assert docs["kvh-b"]["streams"]["aligned"] <= 8.0 * 200
    assert [docs[name]["ended"] for name in ("kvh-a", "xsens")] == ["completed", "completed"]
    index = json.loads((out / "result.json").read_text())
    assert index["ended"] == "early: unit kvh-b did not complete"


def test_a_unit_whose_port_cannot_be_opened_is_refused_naming_the_unit_and_the_port(tmp_path, capsys):
    cfg = units_config()
    cfg["turntable"].update(source="serial", data_port="/dev/null")
    for k, unit in enumerate(cfg["units"]):
        unit["imu"] = {"protocol": unit["imu"]["protocol"], "source": "serial", "port": f"/dev/hil-absent-{k}",
                       "options": {"check_config": False}}
    code = main(["run", str(write(tmp_path, cfg)), "--duration", "5", "--out", str(tmp_path / "run"),
                 "--no-history", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "units[0] (kvh-a)" in err and "/dev/hil-absent-0" in err and "Traceback" not in err


def test_an_optional_unit_whose_port_cannot_be_opened_is_filed_absent_and_the_others_run(tmp_path, capsys):
    """``units[i].optional``: the unit is left out with its port's error, the others run attached late to the
    devices streaming in their own process, and the index files it as ABSENT, a skipped test in junit.xml."""
    cfg = units_config(duration_s=60.0)
    devices = write(tmp_path, {**cfg, "units": [cfg["units"][0], cfg["units"][2]]}, "devices.yaml")
    proc, ports = spawn_emulator(devices, tmp_path / "ports.json", EmulatorRun("1", 30.0))
    try:
        lab = lab_units({**cfg, "units": [cfg["units"][0], cfg["units"][2]]}, ports)
        absent = {**cfg["units"][1], "optional": True,
                  "imu": {"protocol": "kvh1750", "source": "serial", "port": "/dev/hil-absent-1"}}
        lab["units"].insert(1, absent)
        out = tmp_path / "run"
        code = main(["run", str(write(tmp_path, lab, "lab.yaml")), "--duration", "6", "--out", str(out),
                     "--no-history", "--no-figures", "--quiet", "--viewer", "none"])
    finally:
        stop_emulator(proc)
    err = capsys.readouterr().err
    index = json.loads((out / "result.json").read_text())
    UnitsResult.model_validate(index, strict=True)
    lines = {unit["name"]: unit for unit in index["units"]}
    assert code in (0, 3) and index["ended"] == "completed", (index, err)
    assert lines["kvh-b"]["verdict"] == "ABSENT" and lines["kvh-b"]["out_dir"] is None
    assert lines["kvh-b"]["ended"].startswith("absent: ") and "/dev/hil-absent-1" in lines["kvh-b"]["ended"]
    assert "unit kvh-b: absent (units[1].optional)" in err and not (out / "units" / "kvh-b").exists()
    assert not (out / "fixture.rrd").exists()  # --viewer none: no overview either
    assert all(lines[name]["ended"] == "completed" for name in ("kvh-a", "xsens"))
    skipped = [s for s in ET.parse(out / "junit.xml").getroot() if s.get("name") == "units-live/kvh-b"]
    assert len(skipped) == 1 and skipped[0].find("testcase/skipped") is not None


def lab_units(cfg: dict, ports: dict) -> dict:
    """The units config in the lab form: each unit's IMU on its port of the running emulator, the table's data
    port, no emulated truth."""
    lab = copy.deepcopy(cfg)
    lab["turntable"].update(source="serial", data_port=ports["turntable_data"])
    for unit in lab["units"]:
        unit["imu"] = {"protocol": unit["imu"]["protocol"], "source": "serial",
                       "port": ports["units"][unit["name"]]["imu"]}
    return lab


@lab_tests
def test_lab_form_units_attached_late_each_paired_and_one_power_cycled_on_its_own(tmp_path):
    """``hil emulate`` of three units in its own process, streaming; the harness attached seconds later; kvh-b
    loses power for 1 s mid-trial and counts from zero: it alone is re-paired, every unit completes within 5
    sigma of its own truth."""
    cfg = units_config(60.0, **{"kvh-b": {"power_cycle_at_s": 12.0, "power_cycle_s": 1.0}})
    cfg["output"]["limits"] = {"missing_max": 0.05}  # kvh-b's 1 s of 30 lost
    with Emulator(tmp_path, cfg) as emulator:
        lab = write(tmp_path, lab_units(cfg, emulator.ports), "lab.yaml")
        time.sleep(max(0.0, 3.0 - (time.monotonic() - emulator.started)))
        out = tmp_path / "run"
        code = main(["run", str(lab), "--duration", "30", "--out", str(out), "--no-history", "--no-figures",
                     "--quiet"])
    docs = unit_results(out)
    assert code == 0, {name: doc["ended"] for name, doc in docs.items()}
    for name, doc in docs.items():
        sync = doc["streams"]["sync"]
        assert sync["paired_by"] == "motion", (name, sync)
        assert within(doc, TRUTHS[name]), (name, doc["estimate"])
        assert (len(sync["repairs"]) >= 1) == (name == "kvh-b"), (name, sync["repairs"])



def test_a_units_trial_ends_a_unit_whose_imu_or_the_table_is_silent_for_the_outage_limit(tmp_path):
    """The other units' data keep a unit's fan-out busy: its own IMU, or the shared table, silent for
    ``output.outage_limit_s`` (or silent from the start for 15 s) ends its trial, naming the stream and port."""
    from drivers.reader import DeviceReader
    from hil.trial.live import LiveSettings, LiveTrial, TrialAborted, TrialHooks
    from hil.trial.rig import data_links, table_transport
    from hil.vocabulary import DevicePorts

    cfg = parse_config(units_config(), units=True).unit_configs()["kvh-a"]
    cfg = cfg.model_copy(update={"output": cfg.output.model_copy(update={"outage_limit_s": 3.0}),
                                 "imu": cfg.imu.model_copy(update={"options": {"check_config": False}})})
    ports = DevicePorts("/dev/imu-a", "/dev/table")
    table = DeviceReader(table_transport(cfg, ports))
    trial = LiveTrial(LiveSettings.of(cfg), "", tmp_path, None, data_links(cfg, ports, table.transport),
                      hooks=TrialHooks(table_reader=table))
    try:
        assert [r.transport.stream for r in trial.readers] == ["imu"] and table.raw_listeners == [trial.fanout]
        trial.fanout.last_arrival = trial.fanout.last_by_stream["table"] = 100.0
        with pytest.raises(TrialAborted, match=r"^no data from the imu \(/dev/imu-a\) within 15 s$"):
            trial._check_alive(100.5, started=80.0)
        trial.fanout.last_by_stream["imu"] = 97.0
        trial._check_alive(99.9, started=80.0)  # 2.9 s: it goes on
        with pytest.raises(TrialAborted, match=r"^no data from the imu \(/dev/imu-a\) for 3 s \(output.outage_limit_s\)$"):
            trial._check_alive(100.1, started=80.0)
        trial.fanout.last_by_stream.update(imu=110.0, table=106.0)
        trial.fanout.last_arrival = 110.0
        with pytest.raises(TrialAborted, match=r"^no data from the table \(/dev/table\) for 3 s"):
            trial._check_alive(110.1, started=80.0)
        trial._leave_shared()
        assert table.raw_listeners == []
    finally:
        trial.recorder.close()


def test_the_console_shows_every_unit_in_one_line():
    import io

    from rich.console import Console

    from hil.viewer.console_progress import ConsoleProgress, UnitsProgress

    text = io.StringIO()
    with ConsoleProgress(60.0, console=Console(file=text, width=120, force_terminal=False)) as console:
        units = UnitsProgress(console, ["kvh-a", "xsens"])
        units.updater("xsens")(12.4, None, {})
    assert text.getvalue().strip() == "12/60 s | kvh-a acquiring | xsens acquiring"


@pytest.mark.slow
def test_three_units_are_calibrated_in_one_schedule_each_through_its_own_mounting(tmp_path):
    """configs/calibration_units.yaml on a shorter schedule: the first unit commands the table, the others follow;
    every term of every unit within 4 sigma of its own truth, each unit's calibration.json, the table Off at the
    end."""
    from hil.outputs.calibration_report import comparison

    cfg = yaml.safe_load(Path("configs/calibration_units.yaml").read_text())
    cfg["turntable"]["limits"] = {"rate_dps": [60, 60, 60], "accel_dps2": [120, 120, 120]}
    cfg["calibration"] = {"positions": 18, "dwell_s": 4, "settle_s": 0.5, "plateau_rate_dps": 30, "plateau_s": 10}
    out = tmp_path / "run"
    code = main(["calibrate", str(write(tmp_path, cfg)), "--speed", "max", "--out", str(out), "--no-history",
                 "--no-figures", "--quiet"])
    index = json.loads((out / "result.json").read_text())
    assert code == 0, index
    for unit in cfg["units"]:
        doc = json.loads((out / "units" / unit["name"] / "calibration.json").read_text())
        rows = comparison(doc)
        judged = [row for row in rows if row["error_sigma"] is not None]
        assert len(judged) == len(rows) - 1 and all(abs(row["error_sigma"]) < 4.0 for row in judged), \
            (unit["name"], [(row["term"], row["error_sigma"]) for row in judged if abs(row["error_sigma"]) >= 4.0])
    assert json.loads((out / "emulator.json").read_text())["table_modes"] == "Off,Off,Off"


def test_the_noise_of_each_unit_of_an_emulated_units_config_is_analysed_on_its_own(tmp_path):
    """``hil noise`` of a units config: each unit's record, its own noise.json in OUT/units/<name>/, its angle random
    walk its own noise's, sigma / sqrt(rate) (1 deg/h at 200 Hz: 60 / 3600 / sqrt(200) deg/sqrt(h))."""
    cfg = units_config(300.0)
    cfg["turntable"]["motion"] = {"kind": "static"}
    cfg["units"][2]["imu"]["errors"]["gyro_noise_dph"] = [1.0, 1.0, 1.0]
    out = tmp_path / "noise"
    assert main(["noise", str(write(tmp_path, cfg)), "--out", str(out), "--no-history", "--no-figures"]) == 0
    for name, gyro_noise_dph in (("kvh-a", 0.01), ("kvh-b", 0.01), ("xsens", 1.0)):
        doc = json.loads((out / "units" / name / "noise.json").read_text())
        assert doc["record"]["dut_serial"] == name.upper() and doc["trial"]["name"] == f"units-live.{name}"
        arw = gyro_noise_dph * 60.0 / 3600.0 / np.sqrt(200.0)
        assert np.allclose(doc["gyro"]["arw_deg_per_sqrt_h"], arw, rtol=0.05), (name, doc["gyro"])


@pytest.fixture(scope="module")
def saved_views(tmp_path_factory) -> Path:
    """The output directory of a 20 s units trial run as fast as it goes with ``--viewer save``."""
    tmp = tmp_path_factory.mktemp("units-views")
    out = tmp / "run"
    main(["run", str(write(tmp, units_config())), "--speed", "max", "--duration", "20", "--out", str(out),
          "--no-history", "--no-figures", "--quiet", "--viewer", "save"])  # fmt: skip
    return out


def test_each_units_view_is_saved_beside_its_outputs_and_ends_with_its_own_verdict(saved_views):
    """``hil run --viewer save`` of a units config: each unit's .rrd in OUT/units/<name>/, named by the unit's trial,
    its bias against its own truth, its /verdict ending as its result.json judges."""
    from tests.test_viewer_record import _rows

    out = saved_views
    for name, truth in TRUTHS.items():
        rows = _rows(out / "units" / name / "recording.rrd")
        result = json.loads((out / "units" / name / "result.json").read_text())
        assert rows["/verdict"][-1][1][0].startswith(f"## Verdict: {result['verdict']}\n")
        assert [value[0] for _, value in rows["/bias/x/truth"]][-1] == pytest.approx(truth[0])


def test_the_fixtures_overview_holds_exactly_the_entities_docs_viewer_names_for_every_unit(saved_views):
    """OUT/fixture.rrd: docs/viewer.md's table of the overview, ``<name>`` each unit, and nothing else."""
    from tests.test_viewer_record import _recorded, documented

    overview = documented()[5]
    assert "/fixture" in overview and "/units/<name>/verdict" in overview
    assert _recorded(saved_views / "fixture.rrd") == {path.replace("<name>", name) for path in overview
                                                      for name in TRUTHS}


def test_the_fixtures_overview_has_every_units_bias_as_it_converged_and_each_units_verdict(saved_views):
    """Every unit's estimate, 3-sigma band and truth per axis in the overview, the rows of its own view (the last
    estimate result.json's); each unit's verdict the text its own /verdict ends with, naming result.json's
    verdict; the fixture's table a row per unit as the index has it; a column of views per unit."""
    from tests.test_viewer_record import _blueprint_views, _rows

    rows = _rows(saved_views / "fixture.rrd")
    index = json.loads((saved_views / "result.json").read_text())
    for name, truth in TRUTHS.items():
        result = json.loads((saved_views / "units" / name / "result.json").read_text())
        own = _rows(saved_views / "units" / name / "recording.rrd")
        bias, sigma = result["estimate"]["accel_bias_ug"], result["estimate"]["accel_bias_sigma_ug"]
        for k, axis in enumerate("xyz"):
            series = {kind: rows[f"/units/{name}/bias/{axis}/{kind}"]
                      for kind in ("estimate", "sigma3_upper", "sigma3_lower", "truth")}
            assert len(series["estimate"]) >= 10  # 1 Hz, from the time the bias is observable to 20 s
            for kind, values in series.items():
                assert values == own[f"/bias/{axis}/{kind}"], (name, axis, kind)  # the unit's own rows, as they came
            last = {kind: values[-1][1][0] for kind, values in series.items()}
            assert series["estimate"][-1][0] == 20.0
            assert last["estimate"] == pytest.approx(bias[k], abs=1e-9)  # float64 scalars
            assert last["sigma3_upper"] - last["sigma3_lower"] == pytest.approx(6 * sigma[k], rel=1e-9)
            assert last["truth"] == pytest.approx(truth[k], rel=1e-12)
        ((t, (text,)),) = rows[f"/units/{name}/verdict"]
        assert result["verdict"] in ("PASS", "FAIL") and text.startswith(f"## Verdict: {result['verdict']}\n")
        assert (t, text) == (own["/verdict"][-1][0], own["/verdict"][-1][1][0])
    start, end = (value[0] for _, value in rows["/fixture"])
    assert start.startswith("## Fixture units-live: running\n") and "| kvh-a | KVH-A | running | — |" in start
    assert end.startswith(f"## Fixture units-live: {index['verdict']} ({index['ended']})\n")
    for unit in index["units"]:
        assert f"| {unit['name']} | {unit['dut_serial']} | {unit['ended']} | {unit['verdict']} |" in end
    origins = {view["origin"] for view in _blueprint_views(saved_views / "fixture.rrd").values()}
    assert origins == {"/fixture"} | {f"/units/{name}/{part}" for name in TRUTHS
                                      for part in ("bias/x", "bias/y", "bias/z", "verdict")}


def _recordings(path: Path) -> dict[str, tuple[str, set[str]]]:
    """Each recording of a .rrd by its name (``RecordingInfo:name``): its application id and entity paths."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    found = {}
    for recording in reader.recordings():
        name, paths = None, set()
        for chunk in reader.stream(store=recording):
            batch = chunk.to_record_batch()
            if chunk.entity_path == "/__properties" and "RecordingInfo:name" in batch.schema.names:
                name = batch.column("RecordingInfo:name").to_pylist()[-1][0]
            paths.add(chunk.entity_path)
        found[name] = (recording.application_id, paths - {"/__properties"})
    return found


def test_the_fixtures_overview_is_a_recording_named_after_the_trial_beside_the_units(saved_views):
    (app,) = {app for app, _ in _recordings(saved_views / "fixture.rrd").values()}
    assert app == "turntable-hil" and list(_recordings(saved_views / "fixture.rrd")) == ["units-live"]
    for name in TRUTHS:
        assert {name: app for name, (app, _) in _recordings(saved_views / "units" / name / "recording.rrd").items()} \
            == {f"units-live.{name}": "turntable-hil"}


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # what the server saves as it goes
def test_the_fixtures_overview_goes_live_to_the_viewer_the_first_units_view_connects_to(tmp_path):
    """Live, the overview joins the units' recordings in the one viewer: a Rerun server saving what it is sent
    (``rerun --save``) gets every unit's recording and the fixture's, the overview ending with the fixture's table."""
    import argparse
    import signal
    import socket
    import subprocess
    from datetime import datetime, timezone

    from hil.commands.trial_outputs import finish_units
    from hil.config import load_config
    from hil.trial.units_live import run_units_live
    from hil.viewer.modes import ViewerOptions
    from hil.viewer.rerun_process import rerun_executable
    from tests.test_viewer_record import _rows

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    received = tmp_path / "received.rrd"
    server = subprocess.Popen([rerun_executable(), "--bind", "127.0.0.1", "--port", str(port), "--save", str(received)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ, "CI": "1"})
    try:
        config = write(tmp_path, units_config(8.0))
        out = tmp_path / "run"
        fixture = run_units_live(load_config(config, True), config, out, None, "max", quiet=True,
                                 viewer=ViewerOptions("save", connect=f"rerun+http://127.0.0.1:{port}/proxy"))
        args = argparse.Namespace(started=datetime.now(timezone.utc), no_figures=True, no_history=True)
        assert finish_units(args, fixture) == 0
        size = -1
        while size != (size := received.stat().st_size if received.exists() else 0):  # until the server has
            time.sleep(1.0)  # written all it was sent
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)
    live = _recordings(received)
    assert {name: app for name, (app, _) in live.items()} == {name: "turntable-hil" for name in (
        "units-live", "units-live.kvh-a", "units-live.kvh-b", "units-live.xsens")}
    assert live["units-live"][1] == _recordings(out / "fixture.rrd")["units-live"][1]  # every entity, live too
    (end,) = [value[0] for _, value in _rows(out / "fixture.rrd")["/fixture"]][1:]
    assert end.startswith("## Fixture units-live: PASS (completed)\n")
