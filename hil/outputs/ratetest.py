"""The rate-table tests' outputs: OUT/scale_factor.json or OUT/frequency_response.json, the residual figure or
the Bode plot, report.html and junit.xml judged against ``output.limits`` (docs/ratetests.md)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from hil.config import ReportLimits
from hil.outputs.figures import pyplot
from hil.outputs.junit import write_junit
from hil.outputs.measurements import overall, rate_test_measurements
from hil.outputs.page_header import page_header
from hil.outputs.result import trial_verdict
from hil.outputs.trial_report import REPORT_NAME, figures_html, html_page, measurement_table

RATETEST_OUTPUTS = ("scale_factor.json", "scale_factor.png", "frequency_response.json", "bode.png", REPORT_NAME,
                    "junit.xml", "config.yaml", "recording.mcap", "ports.json", "emulator.json",
                    "emulator.log")  # the config's copy; live: the trial's
TITLES = {"scale_factor": "Scale factor test", "frequency_response": "Frequency response test"}


def write_ratetest(out: Path, doc: dict, limits: ReportLimits, figures: bool = True) -> str:
    """Write the test's document, its figure (unless not ``figures``), report.html and junit.xml; its verdict."""
    out.mkdir(parents=True, exist_ok=True)
    test = doc["test"]
    (out / f"{test}.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    results = rate_test_measurements(doc, limits)
    judged = trial_verdict(doc["ended"], overall(results))
    image = None
    if figures and any(a.get("steps") or a.get("frequencies_hz") for a in doc["axes"].values()):
        image = residual_figure(doc) if test == "scale_factor" else bode_figure(doc)
        (out / ("scale_factor.png" if test == "scale_factor" else "bode.png")).write_bytes(image)
    write_junit(out, {"trial": doc["trial"], "ended": doc["ended"], "record": doc.get("record")}, results)
    name = doc["trial"]["name"]
    header = page_header(TITLES[test], name, doc.get("record"), doc["ended"], judged)
    body = f"<h2>Measurements</h2>{measurement_table(results)}<h2>Figures</h2>{figures_html([(TITLES[test], image)])}"
    (out / REPORT_NAME).write_text(html_page(header, f"{name}: {judged}", body), encoding="utf-8")
    return judged


def _png(fig) -> bytes:
    """The figure laid out as a PNG; the figure closed."""
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    pyplot().close(fig)
    return buf.getvalue()


def residual_figure(doc: dict) -> bytes:
    """Each gyro's residuals from its fit (ppm of full-scale output, with each step's 1-sigma) against its input
    rate."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for axis, a in doc["axes"].items():
        used = sorted((s for s in a.get("steps", []) if s["residual_ppm"] is not None), key=lambda s: s["input_dps"])
        sigma = [s["sigma_dph"] / 3600.0 / a["full_scale_dps"] / 1e-6 for s in used]  # ppm of full scale
        ax.errorbar([s["input_dps"] for s in used], [s["residual_ppm"] for s in used], sigma, fmt="o-", ms=4,
                    capsize=2, label=f"gyro {axis}")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set(xlabel="input rate (deg/s)", ylabel="residual (ppm of full scale)", title="Scale factor: residuals")
    ax.legend()
    return _png(fig)


def bode_figure(doc: dict) -> bytes:
    """Gain (dB) and phase (deg) per gyro, measured (with 1-sigma bars) and the fitted model."""
    plt = pyplot()
    fig, (gain, phase) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for axis, a in doc["axes"].items():
        f = np.array(a.get("frequencies_hz") or [])
        if not len(f):
            continue
        line = gain.errorbar(f, a["gain_db"], a["gain_sigma_db"], fmt="o", ms=4, label=f"gyro {axis}")[0]
        phase.errorbar(f, a["phase_deg"], a["phase_sigma_deg"], fmt="o", ms=4, color=line.get_color())
        if a.get("model_gain_db"):
            gain.plot(f, a["model_gain_db"], "-", color=line.get_color(), lw=1)
            phase.plot(f, a["model_phase_deg"], "-", color=line.get_color(), lw=1)
    gain.axhline(-3.0103, color="0.6", lw=0.8, ls="--")
    gain.set(xscale="log", ylabel="gain (dB)", title="Frequency response: gyro against the encoder's rate")
    phase.set(xscale="log", xlabel="frequency (Hz)", ylabel="phase (deg)")
    gain.legend()
    return _png(fig)
