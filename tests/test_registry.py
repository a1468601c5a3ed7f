"""One registry per plug-in kind (drivers/registry.py): drivers never import the trial's config, an unknown name is
one error naming the key and the known names, and a third party's controller and chamber, installed as a
distribution with nothing but its module and its entry points, run a trial."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from drivers.registry import CHAMBERS, IMU_CODECS, POWER_SUPPLIES, TABLE_CODECS, TABLE_CONTROLLERS
from hil.config import ConfigError, parse_config
from tests.test_controller_plugin import PLUGIN as TINY_CONTROLLER

ROOT = Path(__file__).resolve().parents[1]
BASE = {"trial": {"duration_s": 10}, "site": {"latitude_deg": 32}}


def config_imports(source: str) -> list[int]:
    """Lines of ``source`` that import hil.config or a name of it, at any level (function bodies included)."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                "import_module", "__import__"):
            names = [arg.value for arg in node.args if isinstance(arg, ast.Constant) and isinstance(arg.value, str)]
        else:
            continue
        if any(name == "hil.config" or name.startswith("hil.config.") for name in names):
            lines.append(node.lineno)
    return lines


@pytest.mark.parametrize("package", ["drivers", "hil/pipeline"])
def test_no_module_of_drivers_or_of_the_pipeline_imports_the_trial_config(package):
    """The device library knows nothing of a trial; the pipeline's stages take their settings
    (:class:`hil.pipeline.settings.PipelineSettings`), not the config."""
    found = [f"{path.relative_to(ROOT)}:{line}" for path in sorted((ROOT / package).rglob("*.py"))
             for line in config_imports(path.read_text())]
    assert not found, found


def test_the_check_sees_an_import_of_the_config_at_every_level():
    source = ("import hil.config\nfrom hil import config\nfrom hil.config import ConfigError\n"
              "def f():\n    from hil.config import Config\n    return importlib.import_module('hil.config')\n"
              "from hil.config_types import Model\n")
    assert config_imports(source) == [1, 2, 3, 5, 6]


@pytest.mark.parametrize(("block", "message"), [
    ({"imu": {"protocol": "nmea"}}, "imu.protocol: 'nmea': unknown; IMU protocols: can-dbc, kvh1750, stim300, "
                                    "xsens-mtdata2"),
    ({"turntable": {"controller": "acutro"}}, "turntable.controller: 'acutro': unknown; table controllers: "
                                              "acutrol, aerosmith"),
    ({"turntable": {"data_protocol": "kvh1750"}}, "turntable.data_protocol: 'kvh1750': unknown; table data "
                                                  "protocols: tts1"),
    ({"environment": {"chamber": {"controller": "f4", "port": "/dev/x"}}},
     "environment.chamber.controller: 'f4': unknown; chamber controllers: watlow-f4"),
    ({"environment": {"power": {"controller": "visa", "port": "TCPIP::h::1::SOCKET"}}},
     "environment.power.controller: 'visa': unknown; power supplies: scpi"),
])
def test_an_unknown_plugin_is_one_error_naming_the_key_and_the_known_names(block, message):
    with pytest.raises(ConfigError) as err:
        parse_config({**BASE, **block})
    assert str(err.value) == f"config: {message}"


def test_each_kind_has_its_entry_point_group_and_its_built_ins():
    kinds = {registry.groups[-1]: registry.names() for registry in
             (IMU_CODECS, TABLE_CONTROLLERS, CHAMBERS, POWER_SUPPLIES)}
    assert kinds == {"turntable_hil.codecs": ["can-dbc", "kvh1750", "stim300", "xsens-mtdata2"],
                     "turntable_hil.table_controllers": ["acutrol", "aerosmith"],
                     "turntable_hil.chambers": ["watlow-f4"], "turntable_hil.power_supplies": ["scpi"]}
    assert IMU_CODECS.groups == ("turntable_hil.imu_codecs", "turntable_hil.codecs")
    assert TABLE_CODECS.names() == ["tts1"]
    assert TABLE_CONTROLLERS.emulated("acutrol").__name__ == "AcutrolTable"
    assert TABLE_CONTROLLERS.options("aerosmith", {}).axis == "outer"


def test_a_config_names_its_controller_without_importing_a_driver():
    """Loading a config (every trial command does, ``hil simulate`` too) imports no controller and no transport."""
    check = ("import sys; from hil.config import parse_config; parse_config({'trial': {'duration_s': 1}, "
             "'site': {'latitude_deg': 32}, 'turntable': {'controller': 'aerosmith', 'controller_options': {}}}); "
             "print(sorted(m for m in sys.modules if m.split('.')[-1] in "
             "('acutrol_controller', 'aerosmith_controller', 'transport', 'serial', 'can')))")
    run = subprocess.run([sys.executable, "-c", check], cwd=ROOT, capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]"


CHAMBER = '''
from pydantic import BaseModel, ConfigDict


class BoxOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    units: str = "C"


class BoxChamber:
    """A chamber that writes what it is told to the file its port names."""

    name = "box"
    Options = BoxOptions

    def __init__(self, port, options=None):
        self.port, self.options = port, options or BoxOptions()

    def say(self, line):
        with open(self.port, "a") as log:
            log.write(line + "\\n")

    def open(self):
        self.say("open")
        return self

    def set_set_point_c(self, value_c):
        self.say(f"set {value_c:g} {self.options.units}")

    def close(self):
        self.say("close")
'''


def install(site: Path) -> None:
    """A distribution of the controller ``tiny`` and the chamber ``box``, as an installer leaves it in ``site``."""
    site.mkdir()
    (site / "tiny_table.py").write_text(TINY_CONTROLLER)
    (site / "box_chamber.py").write_text(CHAMBER)
    info = site / "lab_extras-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: lab-extras\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[turntable_hil.table_controllers]\ntiny = tiny_table:TinyController\n\n"
                                           "[turntable_hil.chambers]\nbox = box_chamber:BoxChamber\n")


def test_a_third_party_controller_and_chamber_run_a_trial(tmp_path):
    install(tmp_path / "site")
    cfg = yaml.safe_load((ROOT / "configs" / "emulated_swing.yaml").read_text())
    cfg["turntable"].update(command_port="emulator", controller="tiny", controller_options={"greeting": "hello"})
    chamber_log = tmp_path / "chamber.log"
    cfg["environment"] = {"chamber": {"controller": "box", "port": str(chamber_log), "options": {"units": "degC"},
                                      "set_point_c": 30.0, "on_exit": 25.0}}
    (tmp_path / "lab.yaml").write_text(yaml.safe_dump(cfg))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "site"), str(ROOT)])}
    hil = [sys.executable, "-m", "hil.cli", "run", "lab.yaml", "--viewer", "none", "--quiet", "--no-history"]
    run = subprocess.run([*hil, "--duration", "12", "--speed", "max", "--no-figures", "--out", "out"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode in (0, 3), run.stderr  # 12 s: completed, perhaps short of a limit
    assert json.loads((tmp_path / "out" / "result.json").read_text())["ended"] == "completed"
    stats = json.loads((tmp_path / "out" / "emulator.json").read_text())
    assert stats["table_modes"] == "off off off" and "SWING inner 13.0 0.125 0.0" in [
        line for line, code in stats["table_log"] if not code]
    assert chamber_log.read_text().splitlines() == ["open", "set 30 degC", "set 25 degC", "close"]

    cfg["environment"]["chamber"]["options"] = {"unit": "F"}
    (tmp_path / "lab.yaml").write_text(yaml.safe_dump(cfg))
    bad = subprocess.run([*hil, "--out", "bad"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert "environment.chamber.options: unit: unknown key (the box options)" in bad.stderr
