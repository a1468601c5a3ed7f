"""The ``hil`` command line's arguments: the parser of every command and its options, checked as they are parsed
(a refusal is one line and exit 2); :mod:`hil.cli` runs the command they name. Only argparse loads here: the
parser alone starts in about 40 ms (``hil --help``, a refused argument)."""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_CONFIG = "configs/emulated_swing.yaml"
CALIBRATION_CONFIG = "configs/calibration.yaml"
RATETEST_CONFIG = "configs/ratetest_acutrol.yaml"
EXIT_CODES = """exit codes:
  0  done (and PASS against output.limits, or no limits judged)
  1  a trial that ended early (devices lost, table not following, interlock, every sample rejected,
     bytes that decode as no frame: output.stream_timeout_s)
     or was interrupted (Ctrl-C, SIGTERM, SIGHUP): table turned off, outputs kept;
     a campaign with failed runs or ended by a signal (outputs of the runs done; --resume goes on)
  2  bad input (config, data file, port, arguments): one line on stderr naming it and the reason
  3  a trial that completed but FAILs against output.limits (see report.html, junit.xml)
130  Ctrl-C while a command starts or writes its outputs (one line)"""


def _config_path(text: str) -> Path:
    """:func:`hil.inputs.resolve_path`, imported when an argument is converted."""
    from hil.inputs import resolve_path

    return resolve_path(text)


def _config_argument(p: argparse.ArgumentParser, default: str = DEFAULT_CONFIG) -> None:
    p.add_argument("config", nargs="?", type=_config_path, default=default,
                   help=f"trial YAML, a path or a shipped config's name (default {default})")


def _live_options(p: argparse.ArgumentParser) -> None:
    from emulators.command import speed_option

    p.add_argument("--speed", default="1", type=speed_option,
                   help="emulated trials: X times real time, or 'max' (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def _trial_options(p: argparse.ArgumentParser, out_default: str = "output.dir or runs/NAME-TIME",
                   viewer_default: str | None = None) -> None:
    from hil.viewer.modes import default_viewer_mode

    _out_options(p, out_default)
    _viewer_options(p, viewer_default or default_viewer_mode())


def _viewer_options(p: argparse.ArgumentParser, default: str) -> None:
    from hil.viewer.modes import VIEWER_MODES

    p.add_argument("--viewer", choices=VIEWER_MODES, default=default,
                   help=f"Rerun viewer: native window, web viewer, .rrd file only, or nothing (default {default})")
    p.add_argument("--bind", default="127.0.0.1", help="address the web viewer listens on (default 127.0.0.1)")


def _out_options(p: argparse.ArgumentParser, out_default: str, figures: str = "the PNG figures") -> None:
    p.add_argument("--out", help=f"output directory (default: {out_default}); one that holds outputs is refused")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs --out holds (another trial's)")
    p.add_argument("--no-figures", action="store_true", help=f"skip {figures}")


def _record_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dut", help="the unit's serial number (record.dut_serial)")
    p.add_argument("--operator", help="who runs the trial (record.operator)")
    p.add_argument("--station", help="the test station (record.station)")


def _history_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--history", metavar="URL", help="the trial history: a SQLite file or a SQLAlchemy URL "
                   "(default $HIL_HISTORY, else history.sqlite under the user's data directory; docs/history.md)")
    p.add_argument("--no-history", action="store_true", help="do not file the trial in the history")


class _Parser(argparse.ArgumentParser):
    """An argument parser whose refusal is one line on stderr naming the argument and the reason, exit 2."""

    def error(self, message: str):
        self.exit(2, f"hil: error: {message} ({self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from emulators.command import add_options as add_emulate_options  # argparse only: no emulator loaded
    from emulators.command import positive, speed_option

    parser = _Parser(prog="hil", description="Turntable IMU trials: emulate, acquire, estimate.",
                                     epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a trial: devices (or their emulators) -> recorder, estimator, viewer")
    _config_argument(p)
    _trial_options(p)
    _record_options(p)
    _history_options(p)
    p.add_argument("--duration", type=positive, help="seconds (default: trial.duration_s)")
    _live_options(p)

    p = sub.add_parser("calibrate", help="multi-position calibration: the harness turns the table through the "
                                         "schedule; OUT/calibration.json")
    _config_argument(p, CALIBRATION_CONFIG)
    _trial_options(p)
    _record_options(p)
    _history_options(p)
    _live_options(p)
    p.add_argument("--simulate", action="store_true",
                   help="the emulated table and IMU in this process, as fast as the CPU allows (no ports, no "
                        "recording; --speed does not apply)")

    p = sub.add_parser("ratetest", help="rate-table tests: gyro scale factor, nonlinearity and asymmetry, or the "
                                        "frequency response; OUT/scale_factor.json or OUT/frequency_response.json")
    p.add_argument("test", choices=("scale-factor", "frequency-response"))
    _config_argument(p, RATETEST_CONFIG)
    _out_options(p, "output.dir or runs/NAME-TIME")
    _record_options(p)
    _history_options(p)
    _live_options(p)
    p.add_argument("--simulate", action="store_true",
                   help="the emulated table and IMU in this process, as fast as the CPU allows (--speed does not apply)")

    p = sub.add_parser("replay", help="re-run the processing on a recording; same results as the live run")
    p.add_argument("source", help="a run directory (its recording.mcap) or a recording file")
    _trial_options(p, out_default="RUN_DIR/replay")
    _history_options(p)

    p = sub.add_parser("simulate", help="emulator straight into the estimator, as fast as possible")
    _config_argument(p)
    _trial_options(p, viewer_default="none")
    _record_options(p)
    _history_options(p)

    p = sub.add_parser("estimate", help="the estimator on a CSV of increments exported from other software")
    p.add_argument("data", help="CSV: t_s, dtheta_[xyz]_rad, dv_[xyz]_mps[, outer_deg, middle_deg, inner_deg]")
    p.add_argument("--config", required=True, type=_config_path, help="trial YAML (trial and site are enough)")
    _out_options(p, "output.dir or runs/NAME-TIME")
    _record_options(p)
    _history_options(p)

    p = sub.add_parser("noise", help="Allan deviation and IEEE noise terms of a config (its devices read, or "
                                     "simulated), run or CSV")
    p.add_argument("source", help="a trial config (devices on ports: a static record acquired into OUT/acquisition; "
                                  "emulated: simulated), a run directory or recording, or a CSV of increments")
    p.add_argument("--duration", type=positive, help="seconds to acquire from devices, or to simulate (default: "
                                                   "trial.duration_s)")
    p.add_argument("--quiet", action="store_true", help="no progress line while acquiring")
    _out_options(p, "runs/noise-NAME", "allan.png")
    p.add_argument("--config", type=_config_path, help="for a CSV of a moving trial: its site and table")
    p.add_argument("--export", type=Path, help="also write the increments analysed as a CSV here")
    p.add_argument("--rerun", action="store_true", help="also write the Allan deviation curves as OUT/noise.rrd "
                                                        "(as --viewer save)")
    _viewer_options(p, "none")
    p.add_argument("--taus", default="octave", help="tau grid of the deviation: octave (default), decade (1, 2, 5 x "
                                                    "10^k s), all (every multiple of the period: n^2/2 operations), "
                                                    "or taus in s such as 1,10,100,3600")
    p.add_argument("--detrend", choices=("none", "linear", "temperature"), default="none",  # allan_detrend.DETRENDS
                   help="taken out before the variance: none (default), linear (each rate's linear trend, the ramp) "
                        "or temperature (the part a polynomial of the IMU's reported temperature explains)")
    _record_options(p)
    _history_options(p)

    p = sub.add_parser("history", help="a unit's trials from the trial history: bias repeatability, drift, "
                                       "calibration and noise terms over time")
    p.add_argument("--dut", help="the unit's serial number (record.dut_serial); default every unit")
    p.add_argument("--since", help="only trials started on or after this date (ISO 8601, UTC)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON (docs/contracts.md)")
    p.add_argument("--out", help="write history.html with the plots into this directory")
    p.add_argument("--history", metavar="URL", help="the history database (default $HIL_HISTORY, else the "
                   "user's data directory)")
    p.add_argument("--sync", action="store_true", help="first file the trials kept in the spool for this history "
                   "(those it could not take when they ran)")

    p = sub.add_parser("campaign", help="Monte Carlo: every sweep point x N seeds of simulated trials on dask.distributed; "
                                        "OUT/runs.parquet, summary.json, campaign.html (exit 1: some runs failed)")
    p.add_argument("spec", help="campaign YAML: {base: CONFIG, runs: N, seed: S, kind: swing|noise|calibration, "
                                   "sweep: {dotted.key: [values]}}")
    p.add_argument("--scheduler", metavar="ADDR", help="an existing cluster's scheduler, tcp://host:8786 (default: a LocalCluster on "
                                       "127.0.0.1)")
    p.add_argument("--workers", type=int, metavar="N", help="LocalCluster: worker processes (default: one a core); --scheduler: "
                                               "wait for this many")
    p.add_argument("--out", help="output directory (default: runs/campaign-SPEC)")
    p.add_argument("--resume", action="store_true", help="go on with OUT/runs.parquet: skip the runs done there")

    p = sub.add_parser("worker", help="dask workers for an existing cluster, with the campaign's worker settings "
                                      "(profiler off, no malloc trim, one thread each); runs until a signal")
    p.add_argument("scheduler", help="the cluster's scheduler, tcp://host:8786")
    p.add_argument("--nworkers", type=int, default=1, metavar="N", help="worker processes (default 1)")
    p.add_argument("--host", help="the address the workers listen on (default: dask's choice)")

    p = sub.add_parser("plan", help="a test plan: trials, power steps and waits in order, resumable; OUT/plan.json, "
                                    "plan.html, junit.xml and each step's outputs in OUT/NN-<kind>/ (docs/plans.md)")
    p.add_argument("plan", type=_config_path, help="plan YAML: {name, config, steps}, a path or a shipped plan's name")
    p.add_argument("--out", help="output directory (default: runs/plan-NAME)")
    p.add_argument("--resume", action="store_true", help="go on with OUT/plan.json: completed steps kept, the "
                                                         "interrupted one run again")
    p.add_argument("--dry-run", action="store_true", help="check every step and print the schedule; nothing moves")
    p.add_argument("--no-figures", action="store_true", help="skip each step's PNG figures")
    p.add_argument("--speed", default="1", type=speed_option,
                   help="emulated devices: X times real time, or 'max' (default 1); also the plan's waits")
    _viewer_options(p, "none")  # the plan's view, each swing and calibrate step's own in the same viewer
    _record_options(p)
    _history_options(p)

    p = sub.add_parser("emulate", help="start the emulated devices on pseudo-terminals and print their ports; "
                                       "their statistics on stderr at the end and on a signal")
    _config_argument(p)
    add_emulate_options(p)

    p = sub.add_parser("report", help="rebuild a trial's or a rate test's report.html and junit.xml from its outputs "
                                      "(exit as its verdict), or a noise characterisation's report.html")
    p.add_argument("dir", help="a trial's output directory (result.json, series.csv, config.yaml), hil ratetest's "
                               "(scale_factor.json or frequency_response.json) or hil noise's (noise.json)")

    p = sub.add_parser("decode", help="decode a raw capture to CSV; counters (auto: and the protocol) as JSON on the "
                                      "last line")
    p.add_argument("protocol", help="a protocol's name (kvh1750, xsens-mtdata2, stim300, tts1, can-dbc, or an "
                                    "installed plug-in's), or auto (named from a byte dump's first 64 kB; not for CAN "
                                    "logs)")
    p.add_argument("file", help="a raw byte dump, or a python-can .blf/.asc log for can-dbc")
    p.add_argument("--out", help="CSV to write (default: stdout is not used; counters only)")
    p.add_argument("--dbc", help="DBC file for can-dbc")
    p.add_argument("--rate", type=positive, default=200.0, help="the device's output rate, Hz (default 200; a STIM300 "
                                                            "needs its sample rate)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="one of the device's output settings, as imu.options takes it (repeatable)")
    return parser
