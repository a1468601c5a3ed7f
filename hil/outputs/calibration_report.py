"""The calibration's comparison with the emulator's truth, its summary in result.json and ``calibration.html``.

The truth as the schedule sees it (``truth.as_observed`` in calibration.json): the injected errors with
the inner gimbal's zero offset folded into the scale and misalignment terms
(:func:`hil.estimation.calibration_model.fold_inner_rotation`), since no table measurement separates
them; the other zero offsets as injected. Each observable term's error is then judged in its sigmas,
an angle's sigma combined with the table encoder's resolution (``tts1``: 1e-6 deg), below which the
reported angles say nothing.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.config import ImuErrors
from hil.estimation.accel_calibration import AccelCalibration
from hil.estimation.calibration_fit import Fit
from hil.estimation.calibration_model import TERMS, Window, fold_inner_rotation
from hil.estimation.gyro_calibration import raw_rate_residuals
from hil.frames import Earth, TableGeometry
from hil.outputs.calibration import ACCEL_KEYS, GYRO_KEYS
from hil.outputs.calibration_section import RESIDUALS_PNG
from hil.outputs.figures import pyplot
from hil.outputs.page_header import page_header
from hil.outputs.trial_report import html_page
from hil.units import ARCSEC, DEG_PER_H, UG

BLOCKS = (("accel", ACCEL_KEYS), ("gyro", GYRO_KEYS))
ENCODER_RESOLUTION_ARCSEC = 1e-6 * 3600.0


def observed_truth(errors: ImuErrors, zero_offset_arcsec: tuple[float, float, float],
                   body_to_mount: np.ndarray | None = None) -> dict:
    """The document's ``accel``/``gyro``/``turntable`` blocks of the injected errors as the schedule sees them,
    for a triad mounted as ``body_to_mount`` says (:attr:`hil.frames.TableGeometry.body_to_mount_matrix`; identity
    by default)."""
    out: dict = {}
    for block, keys in BLOCKS:
        theta = np.zeros(len(TERMS))
        for key, part, unit in keys:
            theta[part] = np.array(getattr(errors, f"{block}_{key}")) * unit
        theta = fold_inner_rotation(theta, zero_offset_arcsec[2] * ARCSEC, body_to_mount)
        out[block] = {key: [float(v) for v in theta[part] / unit] for key, part, unit in keys}
    out["turntable"] = {"zero_offset_arcsec": [zero_offset_arcsec[0], zero_offset_arcsec[1], None]}
    return out


def comparison(doc: dict) -> list[dict]:
    """One row a term: block, key, index, estimate, sigma, truth (as observed) and the error in sigmas."""
    truth = (doc.get("truth") or {}).get("as_observed") or {}
    rows = []
    blocks = [(b, [k for k, _, _ in keys]) for b, keys in BLOCKS if b in doc] + [("turntable", ["zero_offset_arcsec"])]
    for block, keys in blocks:
        for key in keys:
            values = doc[block][key]
            sigmas = doc["turntable"]["zero_offset_sigma_arcsec"] if block == "turntable" else doc["sigma"][block][key]
            truths = (truth.get(block) or {}).get(key) or [None] * len(values)
            for i, (value, sigma, true) in enumerate(zip(values, sigmas, truths, strict=True)):
                ratio = None
                floor = ENCODER_RESOLUTION_ARCSEC if key.endswith("arcsec") else 0.0
                if value is not None and true is not None and sigma is not None and math.isfinite(sigma) \
                        and math.hypot(sigma, floor) > 0:
                    ratio = (value - true) / math.hypot(sigma, floor)
                rows.append({"term": f"{block}.{key}.{i}", "estimate": value, "sigma": sigma, "truth": true,
                             "error_sigma": ratio, "reason": doc["unobservable"].get(f"{block}.{key}.{i}")})
    return rows


def calibration_summary(doc: dict) -> dict:
    """result.json's ``calibration``: the windows, the residuals after calibration and, against the truth,
    the largest error of an observable term in its sigmas."""
    residuals = np.array([p["residual_ug"] for p in doc["positions"]], dtype=float)
    ratios = [abs(r["error_sigma"]) for r in comparison(doc) if r["error_sigma"] is not None]
    return {"file": "calibration.json", "positions": len(doc["positions"]),
            "residual_rms_ug": float(np.sqrt(np.mean(residuals**2))) if residuals.size else None,
            "residual_max_ug": float(np.max(np.abs(residuals))) if residuals.size else None,
            "unobservable": sorted(doc["unobservable"]),
            "worst_error_sigma": max(ratios) if ratios else None}


@dataclass(frozen=True)
class Residuals:
    """Per-window residuals before (error-free model, zero offsets zero) and after calibration (the fitted
    model), SI: accelerometers (N_dwells, 3) m/s^2; gyros (N_windows, 3) rad/s over the dwells then the
    plateaus, None without a gyro fit."""

    accel_before: np.ndarray
    accel_after: np.ndarray
    gyro_before: np.ndarray | None = None
    gyro_after: np.ndarray | None = None


def window_residuals(windows: Sequence[Window], accel: AccelCalibration, gyro: Fit | None, earth: Earth,
                     geometry: TableGeometry) -> Residuals:
    """The :class:`Residuals` of a calibration: the accelerometers' from its stages, the gyros' before
    calibration against the earth and gimbal rates at the encoder angles."""
    if gyro is None:
        return Residuals(accel.raw_residuals, accel.refined.residuals)
    raw = raw_rate_residuals(windows, earth, geometry)
    return Residuals(accel.raw_residuals, accel.refined.residuals, raw, gyro.residuals)


def residual_figure(residuals: Residuals) -> bytes:
    """PNG: per-position specific-force residuals (µg) before and after calibration, and the gyros' (°/h)
    per window (positions, then plateaus P1..) when they were fitted."""
    plt = pyplot()

    panels = [("specific force", "µg", residuals.accel_before / UG, residuals.accel_after / UG)]
    if residuals.gyro_before is not None:
        panels.append(("angular rate", "°/h", residuals.gyro_before / DEG_PER_H, residuals.gyro_after / DEG_PER_H))
    fig, axes = plt.subplots(2, len(panels), figsize=(9 * len(panels), 6), squeeze=False)
    dwells = len(residuals.accel_before)
    for column, (quantity, unit, before, after) in enumerate(panels):
        windows = np.arange(1, len(before) + 1)
        labels = [str(k) if k <= dwells else f"P{k - dwells}" for k in windows]
        for row, (values, title) in enumerate(((before, "before calibration"), (after, "after calibration"))):
            ax = axes[row, column]
            for k, axis in enumerate("xyz"):
                ax.bar(windows + (k - 1) * 0.27, values[:, k], width=0.27, label=axis)
            ax.set_title(f"{quantity} residual per {'position' if column == 0 else 'window'}, {title}")
            ax.set_ylabel(unit)
            ax.set_xticks(windows, labels, fontsize=7)
            ax.grid(alpha=0.3)
        axes[0, column].legend()
        axes[1, column].set_xlabel("position" if column == 0 else "position / plateau")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def write_residual_figure(out: Path, residuals: Residuals) -> bytes:
    """``out/calibration_residuals.png`` (:func:`residual_figure`), drawn before the trial's report, which shows it."""
    png = residual_figure(residuals)
    out.mkdir(parents=True, exist_ok=True)
    (out / RESIDUALS_PNG).write_bytes(png)
    return png


def write_calibration_report(out: Path, doc: dict, result: dict, verdict: str, image: bytes | None = None,
                             extra: str = "") -> Path:
    """``out/calibration.html`` (self-contained: the residual figure ``image``, a PNG, inline), headed by the trial's
    name, record, end and ``verdict`` from its ``result`` (result.json's document); ``extra`` HTML after the rest
    (a calibration over temperature's section)."""
    rows = "".join(
        f"<tr><td>{html.escape(r['term'])}</td><td class='num'>{_fmt(r['estimate'])}</td>"
        f"<td class='num'>{_fmt(r['sigma'])}</td><td class='num'>{_fmt(r['truth'])}</td>"
        f"<td class='num'>{_fmt(r['error_sigma'])}</td><td>{html.escape(r['reason'] or '')}</td></tr>"
        for r in comparison(doc))
    figure = ""
    if image is not None:
        figure = (f'<figure><img alt="residuals per position" '
                  f'src="data:image/png;base64,{base64.b64encode(image).decode()}"><figcaption>Residual of each '
                  "window's mean output against its reference (gravity; the earth rate plus the table's rate) "
                  "before calibration (the error-free model) and after it (the fitted model).</figcaption></figure>")
    body = ("<p class='meta'>Multi-position calibration (2018 three-stage paper). Units as in the term names "
            "(µg, ppm, arcsec, µg/g², °/h). Truth: the injected errors as this schedule sees them (emulated "
            "trials); error / σ with an angle's σ combined with the encoder resolution (1e-6°). A term without an "
            "estimate is null in calibration.json and never applied by imu.calibration.</p>"
            "<table><thead><tr><th>term</th><th>estimate</th><th>1σ</th><th>truth</th><th>error / σ</th>"
            f"<th>why no estimate</th></tr></thead><tbody>{rows}</tbody></table>{figure}{extra}")
    name = str(result["trial"]["name"])
    header = page_header("Calibration", name, result.get("record"), result.get("ended"), verdict)
    path = out / "calibration.html"
    path.write_text(html_page(header, f"{name}: calibration", body), encoding="utf-8")
    return path


def _fmt(value) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value + 0.0:.4g}"  # + 0.0: a negative zero prints as 0"
