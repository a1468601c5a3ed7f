"""Campaigns of kind ``calibration``: the per-term statistics on hand-made rows against their analytic values,
the SPEC's checks of a calibration sweep point, and a small calibration campaign on a LocalCluster of 2
worker processes."""

from __future__ import annotations

import json
import math
import typing
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from hil.campaign.calibration_summary import point_lines, point_summary
from hil.campaign.kinds import KINDS
from hil.campaign.runner import run_campaign
from hil.campaign.runs import run_calibration
from hil.campaign.spec import CampaignSpec, SpecError, load_campaign
from hil.campaign.task import RunTask

ROOT = Path(__file__).resolve().parent.parent
SHORT = ROOT / "configs" / "calibration_short.yaml"


def _spec(tmp_path: Path, **keys) -> Path:
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"base": str(SHORT), "kind": "calibration", "runs": 2, "seed": 5, **keys}))
    return path


def _row(run: int, terms: dict[str, tuple[float, float, float] | None], error: str | None = None) -> dict:
    """A run's row: per term (error, sigma, truth), or None when the run reports it unobservable."""
    row = {"id": f"p000-r{run:04d}", "point": 0, "run": run, "seed": run, "error": error}
    for term, values in terms.items():
        e, sigma, truth = values if values is not None else (None, None, None)
        row.update({f"term.{term}.estimate": None if e is None else truth + e, f"term.{term}.sigma": sigma,
                    f"term.{term}.truth": truth, f"term.{term}.error_sigma": None if e is None else e / sigma})
    return row


def test_term_statistics_of_hand_made_rows_against_their_analytic_values():
    wide = [-1.0, 0.5, 3.5]  # sigma 1: std sqrt(10.5 / 2), two of three within 3 sigma
    narrow = [0.2, -0.4, 0.6]  # sigma 2
    unit = [1.0, -1.0, 0.0]  # sigma 1: std 1
    rows = [_row(k, {"accel.bias_ug.0": (wide[k], 1.0, 60.0), "accel.bias_ug.1": (unit[k], 1.0, 150.0),
                     "gyro.scale_ppm.1": (narrow[k], 2.0, -80.0), "turntable.zero_offset_arcsec.2": None})
            for k in range(3)]
    rows.append({"id": "p000-r0003", "point": 0, "run": 3, "seed": 3, "error": "boom"})
    p = point_summary(0, {"imu.errors.accel_noise_ug": [50, 50, 50]}, rows)
    assert (p["runs"], p["failed"], p["done"]) == (4, 1, 3)
    bias, scale, zero = (p["terms"][t] for t in ("accel.bias_ug.0", "gyro.scale_ppm.1",
                                                 "turntable.zero_offset_arcsec.2"))
    assert zero == {"runs": 0, "unobservable": 3}
    # chi2 with 2 degrees of freedom: F(x) = 1 - exp(-x / 2), so the band is sqrt(-ln(1 - q)) at q = 0.025, 0.975
    band = [math.sqrt(-math.log(0.975)), math.sqrt(-math.log(0.025))]
    assert bias["ratio_band"] == pytest.approx(band) and scale["ratio_band"] == pytest.approx(band)
    assert bias["runs"] == 3 and bias["error_mean"] == pytest.approx(1.0) and bias["sigma_mean"] == 1.0
    assert bias["error_std"] == pytest.approx(math.sqrt(10.5 / 2)) and bias["ratio"] == pytest.approx(math.sqrt(5.25))
    assert bias["within_3sigma"] == pytest.approx(2 / 3) and bias["z_rms"] == pytest.approx(math.sqrt(13.5 / 3))
    assert not bias["ratio_inside"]  # 2.29 > 1.92
    dev = np.array(narrow) - np.mean(narrow)
    assert scale["ratio"] == pytest.approx(math.sqrt(np.sum(dev**2) / 2) / 2.0) and scale["ratio_inside"]
    assert scale["within_3sigma"] == 1.0
    assert p["terms"]["accel.bias_ug.1"]["ratio"] == pytest.approx(1.0)
    # K ~ Binomial(3, 0.05) terms outside: P(K = 0) = 0.95^3 = 0.857 < 0.95 <= P(K <= 1), so one is allowed
    assert (p["ratio_tested"], p["ratio_above"], p["ratio_below"], p["ratio_outside_allowed"]) == (3, 1, 0, 1)
    assert p["consistent"] and p["ratio_expected_outside"] == pytest.approx(0.15)
    family = p["families"]["accel.bias_ug"]  # pooled over the runs of its terms
    assert (family["terms"], family["ratio_min"]) == (2, pytest.approx(1.0))
    assert family["ratio_max"] == pytest.approx(math.sqrt(5.25)) and family["within_3sigma"] == pytest.approx(5 / 6)
    assert family["z_rms"] == pytest.approx(math.sqrt((13.5 + 2.0) / 6))
    assert set(p["families"]) == {"accel.bias_ug", "gyro.scale_ppm"}
    assert p["worst"]["term"] == "gyro.scale_ppm.1"  # |ln 0.25| > |ln 2.29|: a sigma 4 times too large
    lines = point_lines(p)
    assert "consistent: 1 above, 0 below their 95 % band (by chance ~0.2, at most 1)" in lines[0]
    assert "worst gyro.scale_ppm.1 0.252" in lines[0]
    assert "    accel.bias_ug: std(error)/mean(sigma) 1.000-2.291 over 2 terms, within 3 sigma 0.83" in lines[1]
    assert any(line.startswith("    outside its band: accel.bias_ug.0 2.291 (0.159-1.921), within 3 sigma 0.67")
               for line in lines)
    assert "    turntable.zero_offset_arcsec.2: unobservable in 3 of 3 runs" in lines

    # two terms both outside: P(K <= 1) = 1 - 0.05^2 >= 0.95 allows one
    both = point_summary(0, {}, [_row(k, {"accel.bias_ug.0": (e, 1.0, 0.0), "accel.bias_ug.1": (e, 1.0, 0.0)})
                                 for k, e in enumerate(wide)])
    assert (both["ratio_above"], both["ratio_outside_allowed"], both["consistent"]) == (2, 1, False)
    assert "NOT consistent: 2 above, 0 below" in point_lines(both)[0]
    single = point_summary(0, {}, rows[:1])
    assert single["ratio_tested"] == 0 and "too few for statistics" in point_lines(single)[0]
    assert point_lines(point_summary(0, {}, rows[3:])) == ["  base: no run done"]


def test_the_specs_kinds_are_the_wired_ones_and_an_unknown_kind_names_the_key(tmp_path):
    assert typing.get_args(CampaignSpec.model_fields["kind"].annotation) == tuple(KINDS)
    assert load_campaign(_spec(tmp_path)).spec.kind == "calibration"
    with pytest.raises(SpecError, match=r"kind: Input should be 'swing', 'noise' or 'calibration'"):
        load_campaign(_spec(tmp_path, kind="allan"))


def test_a_calibration_point_whose_schedule_leaves_the_table_limits_is_refused_before_any_run(tmp_path):
    with pytest.raises(SpecError, match=r"sweep point calibration.plateau_rate_dps=90: calibration schedule "
                                        r"plateau 1: .* rate 90 deg/s exceeds the table limit 60 deg/s"):
        load_campaign(_spec(tmp_path, sweep={"calibration.plateau_rate_dps": [30, 90]}))


def test_a_calibration_that_ends_without_its_terms_is_a_failed_run_saying_why():
    config = yaml.safe_load(SHORT.read_text())
    config["trial"]["rate_hz"] = 50
    config["calibration"].update(positions=[[0, 0, 0], [0, 90, 0]], dwell_s=1, plateau_s=0)
    config["turntable"]["interlock_trip_at_s"] = 3.0  # during the move to the second position: the axes brake
    row = run_calibration(RunTask("p000-r0000", 0, 0, 7, {}, config))
    assert set(row) == {"id", "point", "run", "seed", "record.dut_part", "record.dut_serial", "record.config_sha256",
                        "error"}  # the task's columns (its record's part among them) and why, no terms
    assert row["error"].startswith("trial early: the schedule did not end") and "(step 2 of 2: moving)" in row["error"]


def test_the_shipped_calibration_example_sweeps_the_dwell_of_the_short_calibration():
    campaign = load_campaign(ROOT / "configs" / "campaign_calibration.yaml")
    assert campaign.spec.kind == "calibration" and campaign.spec.base == "calibration_short.yaml"
    assert campaign.points == [{"calibration.dwell_s": 1}, {"calibration.dwell_s": 2}] and len(campaign.tasks) == 40
    assert campaign.tasks[0].config["calibration"]["positions"] == 18


def test_a_calibration_campaign_on_a_local_cluster_of_two_workers(tmp_path, capsys):
    spec = _spec(tmp_path, sweep={"calibration.positions": [6], "calibration.dwell_s": [1],
                                  "calibration.plateau_s": [2], "imu.errors.accel_noise_ug": [[50] * 3, [200] * 3]})
    assert run_campaign(spec, tmp_path / "o", workers=2) == 0
    table = pq.read_table(tmp_path / "o" / "runs.parquet")
    assert table.num_rows == 4 and table.column("error").null_count == 4
    rows = table.to_pylist()
    assert {row["ended"] for row in rows} == {"completed"} and {row["calibration.positions"] for row in rows} == {6}
    for row in rows:  # the fields of hil/outputs/calibration_report.py comparison, per term
        assert row["term.accel.bias_ug.0.truth"] == pytest.approx(60.0)
        assert row["term.accel.bias_ug.0.error_sigma"] == pytest.approx(
            (row["term.accel.bias_ug.0.estimate"] - 60.0) / row["term.accel.bias_ug.0.sigma"])
        assert row["term.turntable.zero_offset_arcsec.2.estimate"] is None  # unobservable: a column, null
        assert "turntable.zero_offset_arcsec.2" in [row[f"calibration.unobservable.{k}"] for k in range(2)]
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["spec"]["kind"] == "calibration" and summary["runs"] == 4 and summary["failed"] == 0
    for p in summary["points"]:
        assert p["done"] == 2 and p["terms"]["turntable.zero_offset_arcsec.2"] == {"runs": 0, "unobservable": 2}
        assert p["terms"]["accel.bias_ug.0"]["runs"] == 2 and "ratio_band" in p["terms"]["accel.bias_ug.0"]
        assert p["ratio_tested"] >= 25 and p["worst"]["term"] in p["terms"]
        outside = sum(not t["ratio_inside"] for t in p["terms"].values() if "ratio_inside" in t)
        assert p["consistent"] == (outside <= p["ratio_outside_allowed"])  # the flag recounted from the terms
    page = (tmp_path / "o" / "campaign.html").read_text()
    assert "Calibration consistency per sweep point" in page and page.count("data:image/png;base64,") == 3
    out = capsys.readouterr().out
    assert "campaign: 4 runs, 0 failed, on 2 workers" in out and "std(error)/mean(sigma) of" in out
