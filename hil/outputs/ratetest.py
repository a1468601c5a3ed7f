"""The rate-table tests' outputs: OUT/scale_factor.json or OUT/frequency_response.json, the residual figure or
the Bode plot, report.html and junit.xml judged against ``output.limits`` (docs/ratetests.md); ``hil report``
builds the page and junit.xml again from them (:func:`rebuild_ratetest`)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from hil.config import ReportLimits, load_config
from hil.outputs.figures import pyplot
from hil.outputs.html_page import REPORT_NAME, ReportError, figures_html, html_page, measurement_table
from hil.outputs.junit import write_junit
from hil.outputs.measurements import overall, rate_test_measurements
from hil.outputs.page_header import page_header
from hil.outputs.result import trial_verdict

FIGURES = {"scale_factor": "scale_factor.png", "frequency_response": "bode.png"}  # each test's figure
RATETEST_OUTPUTS = (*(f"{test}.json" for test in FIGURES), *FIGURES.values(), REPORT_NAME, "junit.xml",
                    "config.yaml", "recording.mcap", "ports.json", "emulator.json",
                    "emulator.log")  # the config's copy; live: the trial's
TITLES = {"scale_factor": "Scale factor test", "frequency_response": "Frequency response test"}


def write_ratetest(out: Path, doc: dict, limits: ReportLimits, figures: bool = True) -> str:
    """Write the test's document, its figure (unless not ``figures``), report.html and junit.xml; its verdict."""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{doc['test']}.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return _write_report(out, doc, limits, _figure(out, doc) if figures else None)


def ratetest_document(out: Path) -> Path | None:
    """The rate test's document in the directory ``out`` (scale_factor.json or frequency_response.json), or None."""
    return next((out / f"{test}.json" for test in FIGURES if (out / f"{test}.json").is_file()), None)


def rebuild_ratetest(path: Path) -> tuple[Path, str]:
    """``hil report`` of a rate test's directory: report.html and junit.xml again from its document ``path``
    (:func:`ratetest_document`), its figure (drawn when missing) and the limits of its config.yaml (none without
    one); the page and the verdict. ReportError naming the file for a document this version cannot read."""
    out = path.parent
    config = out / "config.yaml"
    limits = load_config(config).limits if config.exists() else ReportLimits()
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        drawn = out / FIGURES[doc["test"]]
        image = drawn.read_bytes() if drawn.exists() else _figure(out, doc)
        return out / REPORT_NAME, _write_report(out, doc, limits, image)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:  # ValueError: JSON that does not parse
        raise ReportError(f"{path}: not a rate test's document this version can read ({type(exc).__name__}: {exc}); "
                          "run hil ratetest again") from None


def _figure(out: Path, doc: dict) -> bytes | None:
    """The test's figure, drawn and written beside its document (None: no step to draw)."""
    if not any(a.get("steps") or a.get("frequencies_hz") for a in doc["axes"].values()):
        return None
    image = residual_figure(doc) if doc["test"] == "scale_factor" else bode_figure(doc)
    (out / FIGURES[doc["test"]]).write_bytes(image)
    return image


def _write_report(out: Path, doc: dict, limits: ReportLimits, image: bytes | None) -> str:
    """report.html and junit.xml of the test's document, with its figure (None: none); the verdict."""
    test = doc["test"]
    results = rate_test_measurements(doc, limits)
    judged = trial_verdict(doc["ended"], overall(results))
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
