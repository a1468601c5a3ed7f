"""The pytest plugin (entry point ``pytest11``): emulated HIL trials as test fixtures in a lab's own CI
(docs/ci.md). Installed with the package; nothing is imported from the harness until a fixture runs.

- ``hil_trial(config, *args, command="simulate", overrides=None)`` runs ``hil COMMAND CONFIG`` in a process
  of its own, into a directory of the test's, and returns its :class:`TrialOutcome`;
- ``hil_emulator(config, *args)`` starts ``hil emulate CONFIG`` in a process of its own and returns its ports
  (the ports JSON), stopping it when the test ends;
- ``@pytest.mark.hil_limits`` (or ``hil_limits("name", ...)``) fails the test on the trial's failed judged
  measurements (all, or those named), each named with its value and limit; a trial that did not complete fails it
  too, and so does a name that is not one of the trial's measurements.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

EMULATOR_START_S = 60.0  # how long hil emulate may take to open its ports


@dataclass(frozen=True)
class Case:
    """One judged measurement of junit.xml: ``outcome`` passed, failed, skipped or error; ``message`` names the
    value and the limit of a failure."""

    name: str
    outcome: str
    message: str


@dataclass(frozen=True)
class TrialOutcome:
    """What a trial command left: its exit code, output directory, result.json and junit.xml's cases."""

    exit_code: int
    out: Path
    result: dict[str, Any]
    cases: tuple[Case, ...]
    stderr: str

    @property
    def failures(self) -> list[Case]:
        """The cases that failed (a limit not met, or the trial not completed)."""
        return [c for c in self.cases if c.outcome in ("failed", "error")]

    @property
    def measurement_names(self) -> frozenset[str]:
        """The names of the trial's measurements (result.json's, judged or not, and junit.xml's cases)."""
        from hil.config import ReportLimits
        from hil.outputs.measurements import measurements

        return frozenset(m.name for m in measurements(self.result, ReportLimits())) | {c.name for c in self.cases}


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "hil_limits(*names): fail the test when a trial run with hil_trial fails "
                                       "one of its judged measurements (all, or those named)")


def read_cases(junit: Path) -> tuple[Case, ...]:
    """The test cases of a trial's junit.xml."""
    cases = []
    for case in ET.parse(junit).getroot().iter("testcase"):
        kinds = {child.tag: child.get("message", "") for child in case}
        outcome = next((o for tag, o in (("failure", "failed"), ("error", "error"), ("skipped", "skipped"))
                        if tag in kinds), "passed")
        message = kinds.get("failure") or kinds.get("error") or kinds.get("skipped") or ""
        cases.append(Case(case.get("name"), outcome, message))
    return tuple(cases)


def _config_file(config: str | Path, overrides: dict[str, Any] | None, where: Path) -> str:
    """The config as given, or a copy in ``where`` with the dotted ``overrides`` set; a config that cannot be
    read fails the test in one line naming it, as the command line would."""
    if not overrides:
        return str(config)
    import yaml

    from hil.campaign.spec import set_key  # a campaign's sweep sets its keys alike
    from hil.inputs import resolve_path

    try:
        doc = yaml.safe_load(resolve_path(str(config)).read_text(encoding="utf-8"))
    except OSError as exc:
        pytest.fail(f"hil_trial: {config}: cannot read: {exc.strerror or exc}", pytrace=False)
    except yaml.YAMLError as exc:
        pytest.fail(f"hil_trial: {config}: not valid YAML: {getattr(exc, 'problem', None) or exc}", pytrace=False)
    for key, value in overrides.items():
        set_key(doc, key, value)
    path = where / f"{Path(str(config)).stem}-overridden.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def _judge(outcome: TrialOutcome, names: tuple[str, ...]) -> None:
    """pytest.fail naming every failed case (of ``names``, when given); a name that is not one of the trial's
    measurements (a typo would otherwise pass for ever) fails it naming the measurements there are."""
    unknown = [name for name in names if name not in outcome.measurement_names]
    if unknown:
        pytest.fail(f"hil_limits: {', '.join(map(repr, unknown))} not a measurement of the trial; its measurements: "
                    f"{', '.join(sorted(outcome.measurement_names))}", pytrace=False)
    failed = [c for c in outcome.failures if not names or c.name in names or c.name == "trial_completed"]
    if failed:
        pytest.fail("; ".join(c.message or c.name for c in failed), pytrace=False)


@pytest.fixture
def hil_trial(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """Run a trial command on a config (a path or a shipped config's name) and return its :class:`TrialOutcome`."""

    def run(config: str | Path, *args: str, command: str = "simulate",
            overrides: dict[str, Any] | None = None) -> TrialOutcome:
        out = tmp_path_factory.mktemp("hil-trial")
        config_file = _config_file(config, overrides, out)
        extra = ["--viewer", "none"] if command in ("run", "calibrate", "replay", "simulate") else []
        extra += ["--speed", "max", "--quiet"] if command in ("run", "calibrate") and "--simulate" not in args else []
        done = subprocess.run([sys.executable, "-m", "hil.cli", command, config_file, "--out", str(out / "out"),
                               "--no-figures", *extra, *args], capture_output=True, text=True, check=False)
        result_file, junit = out / "out" / "result.json", out / "out" / "junit.xml"
        if not result_file.exists():
            pytest.fail(f"hil {command} {config}: exit {done.returncode}, no result.json: {done.stderr.strip()}",
                        pytrace=False)
        outcome = TrialOutcome(done.returncode, out / "out", json.loads(result_file.read_text()),
                               read_cases(junit) if junit.exists() else (), done.stderr)
        marker = request.node.get_closest_marker("hil_limits")
        if marker is not None:
            _judge(outcome, tuple(marker.args))
        return outcome

    return run


@pytest.fixture
def hil_emulator(tmp_path_factory: pytest.TempPathFactory):
    """Start ``hil emulate CONFIG [ARGS]`` in its own process; returns its ports (the ports JSON) once open.
    Every emulator started is stopped when the test ends."""
    children: list[subprocess.Popen] = []

    def start(config: str | Path, *args: str) -> dict[str, Any]:
        where = tmp_path_factory.mktemp("hil-emulator")
        ports_file, log = where / "ports.json", where / "emulator.log"
        with log.open("w") as err:
            child = subprocess.Popen([sys.executable, "-m", "hil.cli", "emulate", str(config), "--ports-file",
                                      str(ports_file), *args], stdout=subprocess.DEVNULL, stderr=err)
        children.append(child)
        deadline = time.monotonic() + EMULATOR_START_S
        while not ports_file.exists():
            if child.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"hil emulate {config}: no ports ({log.read_text().strip() or 'no message'})", pytrace=False)
            time.sleep(0.05)
        return json.loads(ports_file.read_text())

    yield start
    from emulators.process import stop_emulator

    for child in children:
        stop_emulator(child)
