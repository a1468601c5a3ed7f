"""The pytest plugin (docs/ci.md) as a lab uses it: a test file of theirs, run by pytest in a fresh venv where
the package is installed from its wheel (tests/wheel_venv.py), outside the source tree, the plugin found through
its ``pytest11`` entry point. A good config passes; a limit the unit cannot meet fails the test, naming the
measurement, its value and the limit."""

from __future__ import annotations

import re
import subprocess
import xml.etree.ElementTree as ET

import pytest

from hil.pytest_plugin import read_cases
from tests.wheel_venv import install_wheel

pytest_plugins = ["pytester"]

LAB_TESTS = '''
import os
import pytest

SHORT = {"trial.duration_s": 300}


@pytest.mark.hil_limits
def test_our_imu_meets_our_limits(hil_trial):
    outcome = hil_trial("liu2019_sim.yaml", "--dut", "SN-1", overrides={**SHORT, "output.limits": {
        "bias_sigma_ug_max": 20, "bias_error_ug_max": 30}})
    assert outcome.exit_code == 0 and outcome.result["record"]["dut_serial"] == "SN-1"
    assert {c.name for c in outcome.cases} >= {"accel_bias_sigma_x", "accel_bias_error_z"}


@pytest.mark.hil_limits
def test_our_imu_meets_a_limit_too_tight(hil_trial):
    hil_trial("liu2019_sim.yaml", overrides={**SHORT, "output.limits": {"bias_sigma_ug_max": 0.01}})


def test_the_emulator_opens_its_ports(hil_emulator):
    ports = hil_emulator("emulated_swing.yaml", "--duration", "30")
    assert os.path.exists(ports["imu"]) and os.path.exists(ports["turntable_data"])
'''


@pytest.mark.slow
def test_a_labs_test_file_runs_under_pytest_with_the_installed_plugin(tmp_path):
    venv = install_wheel(tmp_path)
    lab = tmp_path / "lab"
    lab.mkdir()
    (lab / "test_our_imu.py").write_text(LAB_TESTS)
    done = subprocess.run([venv.python, "-m", "pytest", "-p", "no:cacheprovider", "-q", "--junitxml=ci.xml",
                           "test_our_imu.py"], cwd=lab, env={**venv.env, "HIL_HISTORY": str(tmp_path / "h.sqlite")},
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 1, done.stdout + done.stderr
    cases = {c.get("name"): c for c in ET.parse(lab / "ci.xml").getroot().iter("testcase")}
    assert cases["test_our_imu_meets_our_limits"].find("failure") is None
    assert cases["test_the_emulator_opens_its_ports"].find("failure") is None
    failure = cases["test_our_imu_meets_a_limit_too_tight"].find("failure")
    assert failure is not None and "accel_bias_sigma_x = " in failure.get("message") and "limit" in failure.get("message")
    plugin = subprocess.run([venv.python, "-c", "import hil.pytest_plugin as p; print(p.__file__)"], cwd=lab,
                            env=venv.env, capture_output=True, text=True, check=True).stdout
    assert plugin.startswith(str(venv.site))


def test_junit_cases_are_read_with_their_outcome_and_message(tmp_path):
    junit = tmp_path / "junit.xml"
    junit.write_text("<testsuites><testsuite><testcase name='a'/><testcase name='b'><failure message='b = 3 µg, "
                     "limit ≤ 1 µg'/></testcase><testcase name='c'><skipped message='no truth'/></testcase>"
                     "</testsuite></testsuites>")
    assert [(c.name, c.outcome, c.message) for c in read_cases(junit)] == [
        ("a", "passed", ""), ("b", "failed", "b = 3 µg, limit ≤ 1 µg"), ("c", "skipped", "no truth")]


TOO_TIGHT = '''
import pytest

TIGHT = {"trial.duration_s": 60, "output.limits": {"bias_sigma_ug_max": 0.01}}


@pytest.mark.hil_limits("accel_bias_sigma_X")
def test_a_typo(hil_trial):
    hil_trial("liu2019_sim.yaml", overrides=TIGHT)


@pytest.mark.hil_limits("accel_bias_sigma_x", "accel_noise")
def test_named_right(hil_trial):
    hil_trial("liu2019_sim.yaml", overrides=TIGHT)
'''


def test_a_marker_naming_no_measurement_fails_the_test_naming_it_and_the_known_names(pytester):
    """On a trial that fails accel_bias_sigma_x/y/z, a typo of the name fails too, never passes unjudged."""
    pytester.makepyfile(test_lab=TOO_TIGHT)
    run = pytester.runpytest("-p", "no:cacheprovider")
    run.assert_outcomes(failed=2)
    text = run.stdout.str()
    assert "hil_limits: 'accel_bias_sigma_X' not a measurement of the trial; its measurements: " in text
    assert "accel_bias_sigma_x, accel_bias_sigma_y, accel_bias_sigma_z" in text and ", gram_rank, " in text
    assert "accel_bias_sigma_x = " in text and "accel_bias_sigma_y = " not in text  # only the names asked for
    assert re.search(r"accel_bias_sigma_x = \d\.\d\d µg, limit ≤ 0\.01 µg", text)  # three digits, as docs/ci.md


def test_a_missing_config_with_overrides_fails_the_test_in_one_line_naming_it(pytester):
    pytester.makepyfile(test_lab='''
def test_missing(hil_trial):
    hil_trial("no_such.yaml", overrides={"trial.duration_s": 60})
''')
    run = pytester.runpytest("-p", "no:cacheprovider")
    run.assert_outcomes(failed=1)
    assert "hil_trial: no_such.yaml: cannot read: No such file or directory" in run.stdout.str()
    assert "FileNotFoundError" not in run.stdout.str() and "Traceback" not in run.stdout.str()
