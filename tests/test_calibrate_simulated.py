"""``hil calibrate --simulate``: the calibration sequence commanding the servo in process, without transports."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from test_calibrate_trial import calibration_config

from drivers.acl import AclCommand
from drivers.table_controller import TableError
from drivers.tts1 import UDEG_PER_RAD, Tts1Codec
from emulators.clocks import DeviceClock
from emulators.motion import Swing
from emulators.servo import Servo
from emulators.servo_simulation import ServoSimulation
from emulators.sources import TableSource, encoder_reading
from emulators.truth import Truth
from hil.cli import main
from hil.config import DeviceTiming, TurntableConfig, load_config
from hil.frames import Earth, TableGeometry
from hil.outputs.calibration import write_calibration
from hil.outputs.calibration_report import comparison
from hil.trial.calibration_outcome import CalibrationOutcome, checked_schedule
from hil.trial.calibration_sequence import CalibrationSequence, StepWindow
from hil.trial.calibration_settings import CalibrationSettings
from hil.trial.calibration_simulation import run_calibration_simulation
from hil.trial.outcome import OutputSettings, TrialOutcome
from hil.units import ARCSEC, DEG

SHORT = {"dwell_s": 2, "plateau_s": 5}  # the live test's schedule with shorter windows
RATE_HZ = 200  # trial.rate_hz of calibration_config


@pytest.fixture
def servos(monkeypatch) -> list[ServoSimulation]:
    """The simulations the runs build, to look at their servo afterwards."""
    made: list[ServoSimulation] = []
    build = ServoSimulation.from_config.__func__

    def keep(cls, cfg):
        made.append(build(cls, cfg))
        return made[-1]

    monkeypatch.setattr(ServoSimulation, "from_config", classmethod(keep))
    return made


def test_a_simulated_calibration_recovers_every_term_and_leaves_the_table_off(tmp_path, capsys, servos):
    out = tmp_path / "out"
    code = main(["calibrate", str(calibration_config(tmp_path, **SHORT)), "--simulate", "--viewer", "none",
                 "--out", str(out), "--no-figures"])
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "calibration.json").read_text())
    rows = comparison(doc)
    judged = [r for r in rows if r["error_sigma"] is not None]
    assert len(judged) == len(rows) - 1 and "turntable.zero_offset_arcsec.2" in doc["unobservable"]
    errors = np.array([r["error_sigma"] for r in judged])
    assert np.all(np.abs(errors) < 4.0), [(r["term"], r["error_sigma"]) for r in judged]
    assert np.sqrt(np.mean(errors**2)) < 1.5
    # no reading is lost in process: every window holds exactly its dwell's samples
    assert [p["samples"] for p in doc["positions"]] == [SHORT["dwell_s"] * RATE_HZ] * 18
    result = json.loads((out / "result.json").read_text())
    assert result["ended"] == "completed" and result["calibration"]["residual_max_ug"] < 30
    assert (out / "calibration.html").exists() and not (out / "recording.mcap").exists()
    (sim,) = servos
    assert sim.table.offs == 1  # sent Off at the end, once
    assert sim.table.modes() == "Off,Off,Off"
    assert sim.table.received[":Demand:Rate"] == 6  # both signs about each axis


def test_the_same_seed_gives_the_same_calibration_and_nothing_is_written_until_asked(tmp_path):
    path = calibration_config(tmp_path, positions=6, dwell_s=1, plateau_s=2)
    cfg = load_config(path)
    written = []
    for run in ("first", "second"):
        outcome, _ = run_calibration_simulation(cfg, path.read_text(), tmp_path / run)
        assert not (tmp_path / run).exists()  # a campaign's worker takes the outcome only
        doc = outcome.calibration
        assert doc["accel"]["bias_ug"] and doc["sigma"]["gyro"]["scale_ppm"] and doc["truth"]["as_observed"]
        assert outcome.result["calibration"]["residual_max_ug"] == pytest.approx(
            max(abs(r) for p in doc["positions"] for r in p["residual_ug"]))
        write_calibration(tmp_path / f"{run}.json", doc)
        written.append((tmp_path / f"{run}.json").read_bytes())
    assert written[0] == written[1]


def test_a_bad_calibration_config_is_one_line_naming_the_key(tmp_path, capsys):
    path = calibration_config(tmp_path, dwell_s=-1)
    assert main(["calibrate", str(path), "--simulate", "--viewer", "none", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "calibration.dwell_s" in err and err.count("\n") == 1
    path = calibration_config(tmp_path, positions=[[0, 0, 0], [0, 95, 0]])
    assert main(["calibrate", str(path), "--simulate", "--viewer", "none", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "position 2: middle angle 95 deg is outside the table limits" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_a_table_that_stops_following_ends_the_trial_early_and_off(tmp_path, capsys, servos):
    cfg = yaml.safe_load(calibration_config(tmp_path, positions=[[0, 0, 0], [0, 90, 0]], dwell_s=1,
                                            plateau_s=0).read_text())
    cfg["turntable"]["interlock_trip_at_s"] = 3.0  # during the move to the second position: the axes brake, Off
    path = tmp_path / "trip.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["calibrate", str(path), "--simulate", "--viewer", "none", "--out", str(tmp_path / "out"),
                 "--no-figures"]) == 1
    assert "hil: trial early: the schedule did not end within" in capsys.readouterr().err
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["ended"].endswith("(step 2 of 2: moving)") and "calibration" not in result
    assert not (tmp_path / "out" / "calibration.json").exists()
    assert servos[0].table.modes() == "Off,Off,Off"


def test_the_in_process_table_refuses_as_the_wire_does(tmp_path):
    cfg = load_config(calibration_config(tmp_path))
    client = ServoSimulation.from_config(cfg).command_client(cfg.turntable)
    with pytest.raises(TableError, match=r"refused :Demand:Rate 1,1000: error 3 \(parameter out of range\): rate "
                                         "1000 deg/s exceeds"):
        client.send(AclCommand("Demand:Rate", ("1", 1000.0)))
    assert client.identify().startswith("turntable-hil")
    client.close()  # Off, read back


def test_the_reported_angles_are_what_the_table_frames_decode_to():
    """encoder_reading against the emulated table's own frames, decoded: zero offset, 1e-6 deg grid, the seam."""
    table = TurntableConfig()
    zero = np.array([35.0, 30.0, -20.0]) * ARCSEC
    motion = Swing(np.array([179.9, 40.0, 90.0]) * DEG, np.array([2.1, 1.3, 0.7]), np.zeros(3),
                   np.array([0.0, 0.0, 5.0]) * DEG)
    truth = Truth(Earth.from_degrees(32.0, 10.0), TableGeometry.from_config(table), motion)
    clock = DeviceClock(200.0, 50e-6, DeviceTiming())
    k = np.arange(1, 2001)
    frames = TableSource(clock, 1, zero).compute(k, truth, Servo(table, 200.0, motion))
    codec = Tts1Codec()
    decoded = np.array([codec.decode(e.payload).angles_udeg for e in frames]) / UDEG_PER_RAD
    reported = encoder_reading(truth.angles(clock.latch_times(k, None)), zero)
    assert np.ptp(reported[:, 0]) > 6.0  # across the seam
    np.testing.assert_array_equal(reported, decoded)


def test_a_window_whose_samples_were_all_lost_ends_the_trial_early_with_the_window_named(tmp_path):
    cfg = load_config(calibration_config(tmp_path, positions=[[0, 0, 0]], plateau_s=0))
    settings = CalibrationSettings.of(cfg, simulated=True)
    sequence = CalibrationSequence(checked_schedule(settings), None, 1.0 / RATE_HZ)
    sequence.windows_found.append(StepWindow(sequence.steps[0], 2.0, 6.0))
    sequence._index = len(sequence.steps)  # the schedule went through
    t = np.arange(1, 301) / RATE_HZ  # the samples stop at 1.5 s
    sequence.keep(t, np.zeros((300, 3)), np.zeros((300, 3)), np.zeros((300, 3)))
    outcome = TrialOutcome(OutputSettings.of(cfg), "", tmp_path / "out", {"ended": "completed"}, [])
    calibrated = CalibrationOutcome.of_sequence(outcome, sequence, settings)
    assert calibrated.ended == ("early: calibration position 1: 800 of the 800 samples of its window 2.00..6.00 s "
                                "were rejected or lost (more than 0.00%): no fit on it")
    assert calibrated.calibration is None and "calibration" not in calibrated.result


@pytest.mark.parametrize(("lost", "lacking_max", "fails"), [(1, 0.0, True), (7, 0.01, False), (8, 0.01, True)])
def test_a_window_that_lacks_samples_ends_the_trial_as_soon_as_it_closes(tmp_path, lost, lacking_max, fails):
    """A dwell of 4 s at 200 Hz (800 samples) with ``lost`` of them rejected in its middle (and the one after the
    gap, whose interval is not whole): failed at once, by the samples that close it, beyond ``lacking_max`` of them
    (and one sample, a boundary's rounding)."""
    cfg = load_config(calibration_config(tmp_path, positions=[[0, 0, 0]], plateau_s=0))
    schedule = checked_schedule(CalibrationSettings.of(cfg))
    sequence = CalibrationSequence(schedule, None, 1.0 / RATE_HZ, lacking_max=lacking_max)
    sequence.windows_found.append(StepWindow(sequence.steps[0], 2.0, 6.0))
    t = np.arange(1, 1401) / RATE_HZ
    kept = np.ones(len(t), bool)
    kept[800:800 + lost] = False  # rejected at 4.0 s, inside the window
    sequence.keep(t[:1000][kept[:1000]], *(np.zeros((int(kept[:1000].sum()), 3)),) * 3)
    assert sequence.failure is None  # the window is still open
    sequence.keep(t[1000:][kept[1000:]], *(np.zeros((int(kept[1000:].sum()), 3)),) * 3)
    if fails:
        assert sequence.failure == (f"calibration position 1: {lost + 1} of the 800 samples of its window 2.00..6.00 s "
                                    f"were rejected or lost (more than {lacking_max:.2%}): no fit on it")
    else:
        assert sequence.failure is None and sequence.windows()[0].samples == 800 - lost - 1
