"""``hil ratetest scale-factor|frequency-response CONFIG``: one rate-table test, its settings from the config's
``scale_factor`` or ``frequency_response`` block, into its claimed output directory (docs/ratetests.md)."""

from __future__ import annotations

import argparse
from datetime import datetime, timezone
from functools import partial
from pathlib import Path

from hil.config import load_config
from hil.history.entry import trial_row
from hil.history.filing import file_trial
from hil.outputs.measurements import format_value
from hil.outputs.output_dir import claimed, output_dir
from hil.outputs.ratetest import RATETEST_OUTPUTS, write_ratetest
from hil.outputs.record import run_record
from hil.outputs.result import verdict_exit_code
from hil.trial.ratetest_live import live_steps
from hil.trial.ratetest_runner import run_frequency_response, run_scale_factor, simulate_steps

TESTS = {"scale-factor": ("scale_factor", run_scale_factor), "frequency-response": ("frequency_response",
                                                                                     run_frequency_response)}
SUMMARY = {"scale_factor": (("scale_factor_ppm", "scale_factor_sigma_ppm", "scale factor", "ppm"),
                            ("asymmetry_ppm", "asymmetry_sigma_ppm", "asymmetry", "ppm"),
                            ("nonlinearity_ppm", "nonlinearity_sigma_ppm", "nonlinearity", "ppm"),
                            ("bias_dph", "bias_sigma_dph", "bias", "deg/h")),
           "frequency_response": (("bandwidth_hz", "bandwidth_sigma_hz", "bandwidth", "Hz"),
                                  ("damping", "damping_sigma", "damping", ""),
                                  ("delay_ms", "delay_sigma_ms", "delay", "ms"))}


def ratetest_command(args: argparse.Namespace) -> int:
    """Run the test ``args.test`` names, write its outputs, file it in the history (kind ``scale_factor`` or
    ``frequency_response``), print its summary; the exit code."""
    cfg = load_config(args.config)
    given = {"dut_serial": args.dut, "operator": args.operator, "station": args.station}
    cfg = cfg.model_copy(update={"record": cfg.record.model_copy(update={k: v for k, v in given.items() if v})})
    key, run = TESTS[args.test]
    if args.simulate:
        cfg.emulated_only(str(args.config), "hil ratetest --simulate")
    out = output_dir(args.out, cfg)
    with claimed(out, RATETEST_OUTPUTS, args.overwrite, (Path(args.config),)):
        steps_run = simulate_steps if args.simulate else \
            partial(live_steps, config_path=Path(args.config), out=out, speed=args.speed, quiet=args.quiet,
                    response=key == "frequency_response")
        doc = run(cfg, getattr(cfg, key), steps_run)
        text = Path(args.config).read_text()
        doc["record"] = run_record(cfg.record.model_dump(), text, args.started, datetime.now(timezone.utc))
        (out / "config.yaml").write_text(text)  # the config as given, as every trial keeps it
        verdict = write_ratetest(out, doc, cfg.limits, figures=not args.no_figures)
    if not args.no_history:
        file_trial(args.history, trial_row(doc["test"], out, doc, verdict, history_figures(doc)))
    print(summary(doc, out))
    print(f"  report: {verdict} ({out / 'report.html'})")
    return verdict_exit_code(verdict)


def history_figures(doc: dict) -> dict:
    """The history row's figures: every gyro's fitted terms, keyed ``axis.key`` (its units in the key)."""
    return {f"{axis}.{key}": value for axis, a in doc["axes"].items() for key, value in a.items()
            if isinstance(value, (int, float)) and not isinstance(value, bool)}


def summary(doc: dict, out: Path) -> str:
    """The console's lines: how the test ended and each axis's figures with their 1-sigmas."""
    lines = [f"{doc['trial']['name']}: {doc['test'].replace('_', ' ')} test {doc['ended']} -> {out}"]
    for axis, a in doc["axes"].items():
        shown = []
        for name, sigma_name, label, unit in SUMMARY[doc["test"]]:
            value, sigma = a.get(name), a.get(sigma_name)
            if value is None:
                text = a.get("bandwidth_note") if name == "bandwidth_hz" else "not determined"
            else:
                text = f"{format_value(value, sigma)} ± {format_value(sigma)}"
            shown.append(f"{label} {text} {unit}".rstrip())
        lines.append(f"  gyro {axis}: " + ", ".join(shown))
    return "\n".join(lines)
