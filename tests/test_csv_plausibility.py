"""A CSV of increments is held to the live trial's physical plausibility: an absurd value is refused in one line
naming the file, line and column, never estimated into NaN."""

import subprocess
import sys

import numpy as np
import pytest
import yaml

from hil.recording.csv_input import DataError, read_increments_csv
from tests.helpers import make_config

HEADER = "t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps"
T = 0.01  # s, the sample interval


def _static_csv(path, n=3000, rate_x=0.0, bad=None, outer_dps=None):
    """``n`` rows of a static IMU at 100 Hz turning at ``rate_x`` rad/s about x (with ``outer_dps``, table angles:
    the outer gimbal turning at that rate from 170 deg, wrapped to +-180); ``bad`` (line, column, value) written
    over one cell (line 2 is the first data row)."""
    rng = np.random.default_rng(5)
    header = HEADER + ("" if outer_dps is None else ",outer_deg,middle_deg,inner_deg")
    rows = [header]
    for k in range(n):
        d = rng.standard_normal(6) * 1e-6
        angles = [] if outer_dps is None else [(170.0 + outer_dps * (k + 1) * T + 180.0) % 360.0 - 180.0, 0.0, 0.0]
        rows.append([(k + 1) * T, rate_x * T + d[0], d[1], d[2], d[3], d[4], 9.8 * T + d[5], *angles])
    if bad is not None:
        line, column, value = bad
        rows[line - 1][header.split(",").index(column)] = value
    path.write_text("\n".join(r if isinstance(r, str) else ",".join(repr(float(v)) for v in r) for r in rows) + "\n")
    return path


def test_an_absurd_increment_is_refused_naming_file_line_and_column_and_nothing_is_written(tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump(make_config(duration=30, kind="static").model_dump(mode="json",
                                                                                          exclude_none=True)))
    data = _static_csv(tmp_path / "d.csv", bad=(501, "dv_x_mps", 1e308))
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "estimate", str(data), "--config", str(config),
                           "--out", str(tmp_path / "o"), "--no-figures", "--no-history"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "Warning" not in proc.stderr and "nan" not in proc.stdout
    assert f"{data}:501: dv_x_mps 1e+308 is physically implausible" in proc.stderr
    assert not (tmp_path / "o" / "result.json").exists()


def test_a_rotation_beyond_the_tables_rate_limits_is_refused_and_within_them_taken(tmp_path):
    """300 deg/s is more than twice the default 100 deg/s limit, less than twice a 200 deg/s table's."""
    path = _static_csv(tmp_path / "spin.csv", n=200, rate_x=np.radians(300))
    with pytest.raises(DataError, match=r"spin\.csv:2: dtheta_x_rad 0\.0523\d* is physically implausible: a rotation "
                                        r"1\.5 times the fastest the table allows \(2 x 100 deg/s\)"):
        read_increments_csv(path)
    fast = make_config(turntable={"limits": {"rate_dps": [200.0, 200.0, 200.0]}})
    assert len(read_increments_csv(path, fast)) == 200


def test_a_specific_force_far_from_gravity_is_refused_and_a_gap_is_not(tmp_path):
    """A gap in t_s (a missing sample: its neighbour's increments still cover one interval) keeps the file's
    sample interval; increments of zero (no gravity) do not come from an IMU on a table."""
    path = _static_csv(tmp_path / "gap.csv", n=200)
    lines = path.read_text().splitlines()
    del lines[50]
    path.write_text("\n".join(lines) + "\n")
    assert len(read_increments_csv(path)) == 199
    zero = _static_csv(tmp_path / "zero.csv", n=200, bad=(80, "dv_z_mps", 0.0))
    with pytest.raises(DataError, match=r"zero\.csv:80: dv_x_mps, dv_y_mps, dv_z_mps is physically implausible: "
                                        r"a specific force of 1\.83e-05 g, not within 0\.2 g of gravity"):
        read_increments_csv(zero)


def test_a_table_angle_beyond_the_tables_rate_is_refused_and_a_wrapped_one_is_not(tmp_path):
    turning = _static_csv(tmp_path / "turning.csv", n=200, outer_dps=50.0)  # crosses +-180 deg at t = 0.2 s
    batch = read_increments_csv(turning)
    assert batch.angles[:, 0].max() > np.radians(179) and batch.angles[:, 0].min() < np.radians(-179)
    absurd = _static_csv(tmp_path / "absurd.csv", n=200, outer_dps=50.0, bad=(120, "outer_deg", 1e308))
    with pytest.raises(DataError, match=r"absurd\.csv:120: outer_deg 1e\+308 is physically implausible: a turn of "
                                        r"[\d.]+ deg in the 0\.01 s since the row before, beyond the 2 x 100 deg/s"):
        read_increments_csv(absurd)
