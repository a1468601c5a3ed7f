"""Check that ``--viewer serve`` serves a page that renders the trial in headless Chromium.

    apt-get install chromium                    (Debian's package: /usr/bin/chromium)
    .venv/bin/pip install -e '.[webcheck]'      (Python Playwright; its own browsers are not needed)
    .venv/bin/python benchmarks/web_viewer_check.py [--layout trial|calibration|noise|plan|units] [--out web_viewer.png]
        [--timeout 600]

Logs a 60 s emulated swing (``--layout calibration``: and a calibration's first steps and windows)
through a serving ``TrialViewer`` with the default trial's ``output.limits`` (the verdict so far)
(``--layout noise``: the Allan deviation of a simulated static hour at 50 Hz as it forms, ``AllanView``;
``--layout plan``: a plan's view at its second step and that step's own view in the same viewer;
``--layout units``: the fixture's overview, ``FixtureView``, of configs/emulated_units.yaml's three units,
each unit's simulated 60 s swing, its verdict and the fixture's table, in a web viewer started for it),
checks that the web and gRPC servers listen on 127.0.0.1 only, opens the printed URL in headless
Chromium with software WebGL (``--use-gl=angle --use-angle=swiftshader --enable-unsafe-swiftshader``,
tests/pages.py's ``SOFTWARE_GL``) and saves a screenshot at 1600x1000 (docs/viewer.md's,
``docs/images/viewer_<layout>.png``). The page takes in the data in a small window, where a frame costs
little, until the viewer's recording holds every row of the .rrd on screen (the trial's, the noise view's, a
plan's step's, the fixture's overview's); it is then drawn full size, and the screenshot taken once two in a
row are the same. No fixed wait: ``--timeout`` bounds each of the three.

Requests the page makes to hosts other than 127.0.0.1 are blocked (the check needs no network)
and listed: the Rerun web viewer itself asks for a web font, its release and example lists and
its own usage analytics; on a machine without internet access these fail without harm.
Exit status 0 when the page loaded and the screenshot was written.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from emulators.simulation import Simulation  # noqa: E402
from hil.config import load_config  # noqa: E402
from hil.estimation.calibration_schedule import default_schedule  # noqa: E402
from hil.config import Config  # noqa: E402
from hil.estimation.online import OnlineEstimator, Snapshot  # noqa: E402
from hil.outputs.judgement import judge  # noqa: E402
from hil.outputs.noise import ADEV_UNITS  # noqa: E402
from hil.outputs.units_index import SEVERITY  # noqa: E402
from hil.trial.noise_runner import analyse_record, show_forming, simulated  # noqa: E402
from hil.trial.viewer_feed import bias_truth  # noqa: E402
from hil.units import UG  # noqa: E402
from hil.viewer.allan_view import AllanView  # noqa: E402
from hil.viewer.fixture_view import FixtureView  # noqa: E402
from hil.viewer.plan_view import PlanView, plan_markdown  # noqa: E402
from hil.viewer.bias_view import BiasTruth  # noqa: E402
from hil.viewer.modes import ViewerOptions  # noqa: E402
from hil.viewer.rerun_process import start_viewer, stop_served, telemetry_requested  # noqa: E402
from hil.viewer.trial_viewer import TrialViewer  # noqa: E402
from hil.viewer.verdict import VerdictSoFar, final_markdown  # noqa: E402
from tests.pages import SOFTWARE_GL, open_viewer, settled_screenshot, wait_for_recording  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
LOADING_WINDOW = (400, 250)  # px: the page takes in the data here, where a frame of software rendering costs little
WINDOW = (1600, 1000)  # px: the page drawn, once it holds the data


def listening_addresses(port: int) -> set[str]:
    """Local IPv4/IPv6 addresses listening on ``port`` (Linux /proc/net)."""
    found = set()
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        path = Path(table)
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            fields = line.split()
            address, hex_port = fields[1].split(":")
            if fields[3] == "0A" and int(hex_port, 16) == port and len(address) == width:
                found.add(".".join(str(int(address[i : i + 2], 16)) for i in (6, 4, 2, 0)) if width == 8 else address)
    return found


def log_trial(out: Path, layout: str, connect: str | None = None, plan: str | None = None) -> TrialViewer:
    cfg = load_config("configs/emulated_swing.yaml")  # the default trial, shortened
    cfg = cfg.model_copy(update={"trial": cfg.trial.model_copy(update={"duration_s": 60.0, "rate_hz": 200.0})})
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0)
    viewer = TrialViewer(ViewerOptions("serve", layout=layout, connect=connect, plan=plan), out,
                         geometry=sim.truth.geometry, truth=BiasTruth(np.array([60, 150, 260]) * UG), limits=cfg.limits,
                         recording_name="web-check", blocking=True)
    batches = list(sim.batches(chunk=2000))
    for batch in batches:
        est.update_many(batch)
    viewer.log_snapshots(est.snapshots)  # the time series first: the page draws them as they arrive
    for batch in batches:
        viewer.log_table(batch.t, batch.angles)
    for k in range(1, 61):
        health = {"imu": {"frames": 200 * k, "corrupt": 0, "missing": k // 20, "outages": 0},
                  "table": {"frames": 200 * k, "corrupt": 0, "missing": 0, "outages": 0},
                  "aligner": {"aligned": 200 * k, "queue": 1, "latency_p99_ms": 2.0, "table_lag_ms": 0.01}}  # fmt: skip
        viewer.log_health(float(k), health)
        viewer.log_temperature(float(k), 25.0 + 0.02 * k)  # the IMU warming up a little
    if layout == "calibration":
        log_calibration(viewer)
    viewer.close()
    return viewer


def log_plan(out: Path) -> PlanView:
    """A plan's view at its second step, a swing, and that step's own view sent to the same viewer."""
    kinds = ("power", "swing", "wait", "swing")
    entries = [{"index": k + 1, "kind": kind, "out_dir": f"{k + 1:02d}-{kind}" if kind == "swing" else None,
                "ended": "completed" if k == 0 else None, "verdict": None} for k, kind in enumerate(kinds)]
    view = PlanView("serve", out, "acceptance")
    text = plan_markdown("acceptance", entries, 2, "12.5 min")
    view.show(5.0, text, 2, len(kinds))
    log_trial(out / "02-swing", "trial", view.grpc_url, text).close()
    view.close()
    return view


def log_noise(out: Path) -> AllanView:
    """The noise view of a simulated static hour at 50 Hz: its curves as they form and its terms."""
    cfg = load_config("configs/noise_static.yaml")
    cfg = cfg.model_copy(update={"trial": cfg.trial.model_copy(update={"duration_s": 3600.0, "rate_hz": 50.0})})
    record = simulated(cfg)
    view = AllanView("serve", out, ADEV_UNITS)
    show_forming(view, record, analyse_record(record, "noise"), lambda part: analyse_record(part, "noise"))
    view.close()
    return view


@dataclass
class ServedOverview:
    """The fixture's overview in a web viewer started for it alone (in a units trial the first unit's view starts
    the viewer): ``url``, ``rrd_path`` and ``stop`` as the other layouts' views have them."""

    view: FixtureView
    process: subprocess.Popen
    url: str

    @property
    def rrd_path(self) -> Path:
        return self.view.rrd_path

    def stop(self) -> None:
        self.view.close()
        stop_served(self.process, "serve")


def log_units(out: Path) -> ServedOverview:
    """The fixture's overview of configs/emulated_units.yaml's three units, each its own simulated 60 s swing: their
    snapshots, each unit's verdict and the fixture's table, as a units trial logs them."""
    cfg = load_config("configs/emulated_units.yaml", units=True)
    cfg = cfg.model_copy(update={"trial": cfg.trial.model_copy(update={"duration_s": 60.0, "rate_hz": 200.0})})
    units = cfg.unit_configs()
    process, grpc_url, url = start_viewer("serve", "127.0.0.1", telemetry_requested())
    view = FixtureView(ViewerOptions("serve"), out, cfg.trial.name, blocking=True)
    for name, unit in units.items():
        view.listener(name, unit.record.dut_serial, bias_truth(unit))
    view.open(list(units), grpc_url)
    snapshots = {name: unit_snapshots(unit) for name, unit in units.items()}
    for name, snaps in snapshots.items():
        view.log_snapshots(name, snaps)
    end_units(view, units, snapshots)
    return ServedOverview(view, process, url)


def end_units(view: FixtureView, units: dict[str, Config], snapshots: dict[str, list[Snapshot]]) -> None:
    """Each completed unit's verdict, then the fixture's table from an index like the units' result.json, as a
    units trial ends (hil/commands/trial_outputs.py's ``finish_units``)."""
    rows = []
    for name, unit in units.items():
        judged = judge(unit_result(unit, snapshots[name]), unit.limits)
        view.unit_verdict(name, final_markdown(judged))
        rows.append({"name": name, "dut_serial": unit.record.dut_serial, "ended": "completed",
                     "verdict": judged.verdict})  # fmt: skip
    view.end({"ended": "completed", "verdict": max((row["verdict"] for row in rows), key=SEVERITY.index),
              "units": rows})  # fmt: skip


def unit_snapshots(cfg: Config) -> list[Snapshot]:
    """The 1 Hz snapshots of a unit's simulated trial (its one-unit config)."""
    sim = Simulation.from_config(cfg)
    est = OnlineEstimator(sim.truth.earth, sim.truth.geometry, solve_period=1.0)
    for batch in sim.batches(chunk=2000):
        est.update_many(batch)
    return est.snapshots


def unit_result(cfg: Config, snaps: list[Snapshot]) -> dict:
    """A completed unit's result.json figures of its snapshots and its truth, the document its verdict judges."""
    truth = bias_truth(cfg)
    so_far = VerdictSoFar(cfg.limits, None if truth is None else truth.bias / UG)
    so_far.add(snaps)
    return so_far.result() | {"ended": "completed"}


def log_calibration(viewer: TrialViewer) -> None:
    """A calibration's first three dwells and one plateau, with made-up residuals."""
    schedule = default_schedule()
    steps = list(schedule.dwells) + list(schedule.plateaus)
    rng = np.random.default_rng(1)
    for k in range(3):
        viewer.log_calibration_step(15.0 * k, k, steps)
        viewer.log_calibration_window(15.0 * k + 12.0, rng.normal(0.0, 30.0, 3), rng.normal(0.0, 0.02, 3))
    viewer.log_calibration_step(45.0, len(schedule.dwells), steps)
    viewer.log_calibration_window(58.0, None, rng.normal(0.0, 0.02, 3))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timeout", type=float, default=600.0,
                        help="seconds to wait for the page to load, take in the data and draw, each (default 600)")
    parser.add_argument("--layout", choices=("trial", "calibration", "noise", "plan", "units"), default="trial",
                        help="blueprint layout")
    parser.add_argument("--out", type=Path, default=Path("web_viewer.png"), help="screenshot file")
    parser.add_argument("--chromium", default=CHROMIUM, help=f"browser executable (default {CHROMIUM})")
    args = parser.parse_args()
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("Python Playwright is missing: .venv/bin/pip install -e '.[webcheck]'", file=sys.stderr)
        return 2
    if not Path(args.chromium).exists():
        print(f"{args.chromium} not found: apt-get install chromium", file=sys.stderr)
        return 2

    with tempfile.TemporaryDirectory() as tmp:
        own = {"noise": log_noise, "plan": log_plan, "units": log_units}.get(args.layout)
        viewer = own(Path(tmp)) if own is not None else log_trial(Path(tmp), args.layout)
        shown = Path(tmp) / "02-swing" / "recording.rrd" if args.layout == "plan" else viewer.rrd_path  # on screen
        try:
            web_port = urlsplit(viewer.url).port
            grpc_port = urlsplit(parse_qs(urlsplit(viewer.url).query)["url"][0]).port
            for name, port in (("web viewer", web_port), ("gRPC", grpc_port)):
                print(f"{name} port {port} listens on {sorted(listening_addresses(port))}")
            refused: set[str] = set()
            errors: list[str] = []
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=args.chromium, headless=True, args=list(SOFTWARE_GL))
                page = open_viewer(browser, viewer.url, LOADING_WINDOW, args.timeout, refused, errors)
                wait_for_recording(page, shown, Path(tmp) / "in-viewer.rrd", args.timeout)
                args.out.write_bytes(settled_screenshot(page, WINDOW, args.timeout))
                title = page.title()
                browser.close()
            print(f"page {viewer.url}\n  title {title!r}, screenshot {args.out}")
            print(f"  blocked requests to: {', '.join(sorted(refused)) or 'none'}")
            if errors:
                print(f"  page errors: {len(errors)}, first: {errors[0][:200]}")
        finally:
            viewer.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
