"""The live trial of several units on one table (``hil run`` of a ``units`` config, docs/units.md).

One reader of the table's data, shared: each unit's :class:`~hil.trial.live.LiveTrial` listens to it beside its
own IMU's reader, pairs its IMU with the table on its own, estimates, records (its own recording.mcap, the table's
bytes with its IMU's) and ends on its own, each in its own thread. A unit whose IMU goes silent ends early while the
others go on; the table's loss ends every unit. The table is armed once and sent Off when the last unit ends, and on
every way out; the emulated devices (``hil emulate`` of the units config) run in their own process.
"""

from __future__ import annotations

import dataclasses
import shutil
import threading
from collections.abc import Callable
from pathlib import Path

from drivers.reader import DeviceReader
from drivers.table_controller import InterlockError, LimitError, TableError
from drivers.transport import TransportError
from emulators.process import parse_speed
from hil.config import Config
from hil.outputs.units_index import UNITS_DIR
from hil.trial.live import LiveSettings, LiveTrial, TrialHooks
from hil.trial.outcome import TrialOutcome, TrialSetupError, emulated_truth
from hil.trial.rig import Rig, emulated
from hil.trial.stop_signals import StopSignals
from hil.trial.table_control import MotionCheck, TableControl
from hil.trial.units import FixtureOutcome, unit_config_text
from hil.trial.viewer_feed import ViewerOptions, bias_truth, fixture_view, open_viewer
from hil.viewer.console_progress import ConsoleProgress, UnitsProgress

JOIN_S = 0.2  # how often the main thread looks up from the units' threads (signals are taken meanwhile)


class ListeningClient:
    """What a unit's trial but the first gets for the table's controller: the same gimbals, every command heard and
    not sent. The first unit's trial commands the table; the others follow its reported angles by the same rules."""

    def __init__(self, client) -> None:
        self.gimbals = client.gimbals

    def demand_position(self, gimbal: str, deg: float) -> None:
        """Not sent: the first unit's trial commands the table."""

    def demand_rate(self, gimbal: str, dps: float) -> None:
        """Not sent."""

    def set_mode(self, gimbal: str, mode: str) -> None:
        """Not sent."""


@dataclasses.dataclass(frozen=True)
class UnitsCommand:
    """How the harness drives the table in a units trial: ``arm`` with the open :class:`TableControl` before the
    units' trials are made, ``unit(name, client, cfg)`` each unit's hooks (``client`` the table's controller for
    the first unit, a :class:`ListeningClient` for the others; ``cfg`` the unit's config), ``started`` once every
    unit's trial is made. The default: ``hil run``'s configured motion, each unit checking it."""

    arm: Callable[[TableControl], None] = lambda control: control.arm()
    unit: Callable[[str, object, Config], TrialHooks] = lambda name, client, cfg: TrialHooks(
        motion_check=MotionCheck(cfg.turntable, cfg.trial.rate_hz))
    started: Callable[[TableControl], None] = lambda control: None


@dataclasses.dataclass(frozen=True)
class UnitTrial:
    """One unit's live trial: its name, one-unit config, config text and output directory, and the trial."""

    name: str
    cfg: Config
    config_text: str
    out: Path
    trial: LiveTrial


def run_units_live(cfg: Config, config_path: Path, out: Path, duration: float | None, speed: str,
                   quiet: bool = False, command: UnitsCommand = UnitsCommand(),
                   viewer: ViewerOptions = ViewerOptions()) -> FixtureOutcome:
    """Acquire, record and estimate every unit until each ends, the table driven as ``command`` says, each unit
    in its own view where ``viewer`` asks for one (its .rrd in its directory; live, each unit's recording in the one
    viewer the first unit's view starts), and the fixture's overview beside them (:mod:`hil.viewer.fixture_view`,
    OUT/fixture.rrd); their outcomes."""
    is_emulated = emulated(cfg)
    duration = duration if duration is not None else cfg.trial.duration_s
    if is_emulated and duration is None:
        raise TrialSetupError("an emulated trial needs trial.duration_s or --duration")
    time_scale = parse_speed(speed) if is_emulated else 1.0
    out.mkdir(parents=True, exist_ok=True)
    with StopSignals() as signals:
        trials, absent, ended, overview = _acquire(_Setup(cfg, config_path, out, duration, speed, time_scale, quiet,
                                                          is_emulated, command, viewer), lambda: signals.received)
    return FixtureOutcome(cfg.trial.name, out, {
        unit.name: TrialOutcome.of(unit.trial.finished, unit.cfg, unit.config_text, unit.out, ended[unit.name],
                                   emulated_truth(unit.cfg)) for unit in trials},
        {unit.name: unit.trial.viewer for unit in trials if unit.trial.viewer is not None}, absent, overview)


@dataclasses.dataclass(frozen=True)
class _Setup:
    """What :func:`run_units_live` was asked for."""

    cfg: Config
    config_path: Path
    out: Path
    duration: float | None
    speed: str
    time_scale: float | None
    quiet: bool
    emulated: bool
    command: UnitsCommand
    viewer: ViewerOptions


def _acquire(setup: _Setup, stop_requested) -> tuple[list[UnitTrial], dict[str, tuple[str | None, str]],
                                                     dict[str, str], object | None]:
    """The rig (:class:`~hil.trial.rig.Rig`), the shared table reader and every present unit's trial, run to
    their ends; the trials, the absent optional units (:attr:`FixtureOutcome.absent`), how each trial ended and the
    fixture's overview (None: none, or it did not start)."""
    cfg = setup.cfg
    overview = fixture_view(setup.viewer, cfg, setup.out)
    try:
        with Rig(cfg, setup.config_path, setup.out, setup.speed, setup.duration) as rig, \
                ConsoleProgress(setup.duration, quiet=setup.quiet) as progress:
            hooks = TrialHooks(on_warning=progress.warn, stop_requested=stop_requested, source_done=rig.source_done)
            table = DeviceReader(rig.table_transport(),
                                 gather_s=cfg.read_s if setup.time_scale is not None else 0.0)
            try:
                if rig.table is not None:
                    setup.command.arm(rig.table)
                absent: dict[str, tuple[str | None, str]] = {}
                trials = _unit_trials(setup, rig, dataclasses.replace(hooks, table_reader=table),
                                      UnitsProgress(progress, list(cfg.unit_configs())), absent, overview)
                overview = _opened(overview, trials, progress.warn)
                if rig.table is not None:
                    setup.command.started(rig.table)
                return trials, absent, _run(trials, table, rig.table), overview
            finally:
                table.stop()
                if overview is not None:
                    overview.close()  # the units' verdicts and the fixture's table come with the outputs
    except (TableError, LimitError, InterlockError) as exc:
        raise TrialSetupError(str(exc)) from None


def _unit_trials(setup: _Setup, rig: Rig, hooks: TrialHooks, progress: UnitsProgress,
                 absent: dict[str, tuple[str | None, str]], overview) -> list[UnitTrial]:
    """Each unit's trial on its own IMU port and the shared table reader (``hooks.table_reader``): where the table is
    commanded, its hooks from the command (the first present unit's commanding the table), its warnings named by the
    unit, its progress in the console's one line, its snapshots to the fixture's ``overview`` too (None: none).
    A unit whose port cannot be opened is refused naming the unit and the port; an optional one is left out, added
    to ``absent`` with its port's error, and warned of (every unit absent refuses the trial)."""
    trials: list[UnitTrial] = []
    control = rig.table
    for k, (name, unit) in enumerate(setup.cfg.unit_configs().items()):
        unit_hooks = hooks
        if control is not None:
            client = ListeningClient(control.client) if trials else control.client
            commanded = setup.command.unit(name, client, unit)
            unit_hooks = dataclasses.replace(hooks, motion_check=commanded.motion_check, finished=commanded.finished,
                                             queue_items=commanded.queue_items, early_end=commanded.early_end)
        unit_hooks = dataclasses.replace(
            unit_hooks, on_warning=lambda text, name=name: hooks.on_warning(f"unit {name}: {text}"),
            on_progress=progress.updater(name))
        if overview is not None:
            unit_hooks = dataclasses.replace(unit_hooks, listeners=(
                *unit_hooks.listeners, overview.listener(name, unit.record.dut_serial, bias_truth(unit))))
        unit_out = setup.out / UNITS_DIR / name
        unit_out.mkdir(parents=True, exist_ok=True)
        text = unit_config_text(name, unit)
        options = setup.viewer  # the first unit's view starts the viewer; the others' connect to it
        if trials and trials[0].trial.viewer is not None and trials[0].trial.viewer.grpc_url is not None:
            options = dataclasses.replace(options, connect=trials[0].trial.viewer.grpc_url)
        view = open_viewer(options, unit, unit_out, blocking=False)
        try:
            links = rig.unit_links(name, unit, hooks.table_reader.transport)
            trial = LiveTrial(LiveSettings.of(unit), text, unit_out, setup.duration, links, view, setup.time_scale,
                              unit_hooks)
            _check_opens(trial)
        except TransportError as exc:
            if view is not None:
                view.close()
            if not setup.cfg.units[k].optional:
                raise TrialSetupError(f"units[{k}] ({name}): {exc}") from None
            shutil.rmtree(unit_out, ignore_errors=True)
            absent[name] = (unit.record.dut_serial, str(exc))
            hooks.on_warning(f"unit {name}: absent (units[{k}].optional): {exc}")
            continue
        trials.append(UnitTrial(name, unit, text, unit_out, trial))
    if not trials:
        raise TrialSetupError(f"units: every unit is absent ({', '.join(absent)})")
    return trials


def _opened(overview, trials: list[UnitTrial], warn: Callable[[str], None]):
    """The fixture's overview (None: none) opened with the units that run, live in the viewer the first unit's view
    started; one that does not start is warned of and left out (None), the units' views go on."""
    if overview is None:
        return None
    first = trials[0].trial.viewer
    try:
        overview.open([unit.name for unit in trials], None if first is None else first.grpc_url)
    except Exception as exc:  # noqa: BLE001 - whatever rerun did, the units' trials go on
        warn(f"the fixture's overview did not start: {exc}")
        return None
    return overview


def _check_opens(trial: LiveTrial) -> None:
    """Open and close the trial's own ports: one that cannot be opened refuses the trial before anything starts."""
    for reader in trial.readers:
        reader.transport.open()
        reader.transport.close()


def _run(trials: list[UnitTrial], table: DeviceReader, control: TableControl | None) -> dict[str, str]:
    """Run every unit's trial in its own thread, the table's reader with them; the table Off once the last unit's
    acquisition has ended. How each ended, by unit."""
    ended: dict[str, str] = {}
    failed: list[BaseException] = []
    running = threading.Semaphore(0)
    left = [len(trials)]
    lock = threading.Lock()

    def acquisition_ended() -> None:
        with lock:
            left[0] -= 1
            if left[0] == 0 and control is not None:
                control.stop()

    def run(unit: UnitTrial) -> None:
        try:
            ended[unit.name] = unit.trial.run()
        except BaseException as exc:  # raised again in the main thread
            failed.append(exc)
        finally:
            running.release()

    for unit in trials:
        unit.trial.hooks = dataclasses.replace(unit.trial.hooks, on_end=acquisition_ended)
    try:
        table.start()
    except TransportError as exc:
        raise TrialSetupError(f"turntable.data_port: {exc}") from None
    threads = [threading.Thread(target=run, args=(unit,), name=f"unit-{unit.name}", daemon=True) for unit in trials]
    for thread in threads:
        thread.start()
    for _ in threads:
        while not running.acquire(timeout=JOIN_S):
            pass
    for thread in threads:
        thread.join()
    if failed:
        raise failed[0]
    return ended
