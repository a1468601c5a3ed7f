"""calibration.json of a calibration over temperature (docs/contracts.md, "calibration.json", ``thermal``).

From the calibrations at each temperature (each a document as :func:`hil.outputs.calibration.calibration_document`
gives it), every term with a value at every temperature gets its polynomial in T - ``reference_c``
(:func:`hil.estimation.thermal_calibration.fit_polynomial`; each value at the IMU's temperature over the windows
that estimate it, :func:`term_temperatures`; ``reference_c`` the mean of the IMU's temperatures, to 0.1 deg C) under
``thermal.terms`` keyed ``block.key.index``, coefficients lowest order first in the key's unit per deg C^j; the
``accel`` and ``gyro`` blocks hold the constant terms (the calibration at ``reference_c``) with their sigmas, so
that a reader without ``thermal`` still applies the calibration of the middle of the range. A term null at some
temperature is null, its reasons under ``unobservable`` with the temperatures. ``positions`` lists every
temperature's, each with the IMU's ``temperature_c``; the table's zero offsets are the weighted mean of the
temperatures'. An emulated IMU's truth gains ``thermal.terms`` (its ``imu.errors.thermal`` about ``reference_c``)
and ``as_observed`` at ``reference_c``. calibration.html shows every polynomial's coefficients and, per key, each term
against the IMU's temperature with its fit and the fit's 1-sigma band (:func:`thermal_section`).
"""

from __future__ import annotations

import base64
import html
import io
import math

import numpy as np

from hil.config import ImuErrors
from hil.estimation.thermal_calibration import SIGMA_FLOOR, fit_polynomial, polynomial_at, polynomial_fit
from hil.outputs.calibration_report import BLOCKS, observed_truth
from hil.outputs.figures import pyplot
from hil.units import PPM

# term key -> (the errors.thermal fields of its polynomial's first and second order coefficients)
THERMAL_TRUTH = {("accel", "bias_ug"): ("accel_bias_ug_per_c", "accel_bias_ug_per_c2"),
                 ("accel", "scale_ppm"): ("accel_scale_ppm_per_c", None),
                 ("gyro", "bias_dph"): ("gyro_bias_dph_per_c", None),
                 ("gyro", "scale_ppm"): ("gyro_scale_ppm_per_c", None)}


def _known(value) -> bool:
    return value is not None and math.isfinite(value)


def thermal_document(order: int, points: list[dict], documents: list[dict], errors: ImuErrors | None = None,
                     zero_offset_arcsec: tuple[float, float, float] | None = None) -> dict:
    """The calibration.json mapping from ``documents``, the calibrations at the temperatures ``points``
    (``{set_point_c, chamber_c, imu_c, soak_s, dwells_c, windows_c, gyro_scale_c}`` each), and the IMU's ``errors``
    when emulated (module docstring)."""
    reference = round(float(np.mean([p["imu_c"] for p in points])), 1)
    doc: dict = {"sigma": {}}
    terms: dict[str, dict] = {}
    unobservable: dict[str, str] = {}
    for block, keys in BLOCKS:
        if block not in documents[0]:
            continue
        doc[block], doc["sigma"][block] = {}, {}
        for key, _, _ in keys:
            values, sigmas = [], []
            for i in range(len(documents[0][block][key])):
                name = f"{block}.{key}.{i}"
                v = [d[block][key][i] for d in documents]
                s = [d["sigma"][block][key][i] for d in documents]
                if not all(_known(x) for x in v + s):
                    unobservable[name] = _reasons(name, points, documents)
                    values.append(None)
                    sigmas.append(None)
                    continue
                c, cs = fit_polynomial(term_temperatures(points, name), np.array(v), np.array(s), order, reference)
                terms[name] = {"coefficients": c.tolist(), "sigma": cs.tolist()}
                values.append(float(c[0]))
                sigmas.append(float(cs[0]))
            doc[block][key], doc["sigma"][block][key] = values, sigmas
    doc["turntable"] = _zero_offsets(points, documents, unobservable)
    doc["positions"] = [{**p, "temperature_c": point["imu_c"]} for point, d in zip(points, documents, strict=True)
                        for p in d["positions"]]
    doc["unobservable"] = unobservable
    doc["thermal"] = {"reference_c": reference, "order": order, "terms": terms, "temperatures": [
        {**point, **{k: d[k] for k in ("accel", "gyro", "sigma") if k in d}}
        for point, d in zip(points, documents, strict=True)]}
    if errors is not None:
        doc["truth"] = dict(documents[0]["truth"])
        doc["truth"]["as_observed"], doc["truth"]["thermal"] = thermal_truth(errors, zero_offset_arcsec, reference,
                                                                             order)
    return doc


def term_temperatures(points: list[dict], name: str) -> np.ndarray:
    """The IMU's temperature (deg C) at each of ``points`` that the term ``name`` (``block.key.index``) was estimated
    at: the accelerometers' over the dwells, a gyro's scale factor over the plateaus that turned it, the gyros' other
    terms over every window (:func:`hil.trial.calibration_thermal.window_temperatures`)."""
    block, key, index = name.split(".")
    if block == "accel":
        return np.array([p["dwells_c"] for p in points])
    if key == "scale_ppm":
        return np.array([p["gyro_scale_c"][int(index)] for p in points])
    return np.array([p["windows_c"] for p in points])


def _reasons(name: str, points: list[dict], documents: list[dict]) -> str:
    """Why ``name`` (``block.key.index``) has no value or sigma at some temperature, temperature by temperature."""
    block, key, index = name.split(".")
    return "; ".join(f"at {p['imu_c']:.1f} deg C: {d['unobservable'].get(name, 'its sigma is unknown')}"
                     for p, d in zip(points, documents, strict=True)
                     if not (_known(d[block][key][int(index)]) and _known(d["sigma"][block][key][int(index)])))


def _zero_offsets(points: list[dict], documents: list[dict], unobservable: dict[str, str]) -> dict:
    """The table's zero offsets (arcsec): the mean over the temperatures weighted by their sigmas, and its sigma."""
    values, sigmas = [], []
    for axis in range(3):
        v = [d["turntable"]["zero_offset_arcsec"][axis] for d in documents]
        s = [d["turntable"]["zero_offset_sigma_arcsec"][axis] for d in documents]
        if not all(_known(x) for x in v + s):
            name = f"turntable.zero_offset_arcsec.{axis}"
            unobservable[name] = "; ".join(f"at {p['imu_c']:.1f} deg C: {d['unobservable'].get(name, 'no value')}"
                                           for p, d in zip(points, documents, strict=True))
            values.append(None)
            sigmas.append(None)
            continue
        w = 1.0 / np.maximum(np.array(s), SIGMA_FLOOR) ** 2
        values.append(float(np.sum(w * np.array(v)) / np.sum(w)))
        sigmas.append(float(1.0 / math.sqrt(np.sum(w))))
    return {"zero_offset_arcsec": values, "zero_offset_sigma_arcsec": sigmas}


def thermal_truth(errors: ImuErrors, zero_offset_arcsec, reference_c: float, order: int) -> tuple[dict, dict]:
    """(``as_observed`` at ``reference_c``, ``{reference_c, terms}``): the injected errors as the schedule sees
    them, their ``imu.errors.thermal`` polynomials moved to ``reference_c`` and cut at ``order``.

    The emulator adds the thermal errors to the ideal increments, ahead of the triad's scale factor (emulators/
    thermal.py), so an axis sees each thermal coefficient times 1 + S, S its static scale factor error: the scale
    factor at T is (1 + S)(1 + s dT) - 1. The misalignment's share (arcsec times a thermal bias) is left out."""
    observed = observed_truth(errors, zero_offset_arcsec)
    thermal = errors.thermal
    gains = {block: 1.0 + np.array(observed[block]["scale_ppm"]) * PPM for block, _ in BLOCKS}
    terms = {}
    for block, keys in BLOCKS:
        for key, _, _ in keys:
            for i, base in enumerate(observed[block][key]):
                poly = [base, 0.0, 0.0, 0.0]
                fields = THERMAL_TRUTH.get((block, key))
                if thermal is not None and fields is not None:
                    d0 = reference_c - thermal.reference_c
                    first = getattr(thermal, fields[0])[i] * gains[block][i]
                    second = (getattr(thermal, fields[1])[i] if fields[1] else 0.0) * gains[block][i]
                    poly[:3] = [base + first * d0 + second * d0 * d0, first + 2.0 * second * d0, second]
                observed[block][key][i] = poly[0]
                terms[f"{block}.{key}.{i}"] = poly[:order + 1]
    return observed, {"reference_c": reference_c, "terms": terms}


UNITS = {"bias_ug": "µg", "scale_ppm": "ppm", "misalignment_arcsec": "arcsec", "nonlinearity_ug_per_g2": "µg/g²",
         "bias_dph": "°/h"}


def thermal_section(doc: dict, figure: bool = True) -> str:
    """calibration.html's part of a calibration over temperature: the coefficients with their sigmas (and the
    truth's, emulated) and, with ``figure``, every term against the IMU's temperature (:func:`thermal_figure`)."""
    thermal = doc["thermal"]
    truth = ((doc.get("truth") or {}).get("thermal") or {}).get("terms") or {}

    def listed(values) -> str:
        return ", ".join("—" if v is None else f"{v + 0.0:.4g}" for v in values)

    rows = "".join(f"<tr><td>{html.escape(name)}</td><td class='num'>{listed(term['coefficients'])}</td>"
                   f"<td class='num'>{listed(term['sigma'])}</td>"
                   f"<td class='num'>{listed(truth.get(name, []))}</td></tr>"
                   for name, term in thermal["terms"].items())
    image = ""
    if figure and thermal["terms"]:
        image = (f'<figure><img alt="terms against temperature" src="data:image/png;base64,'
                 f'{base64.b64encode(thermal_figure(doc)).decode()}"><figcaption>Each term at each temperature (its '
                 "calibration there, 1σ bars), its polynomial and the polynomial's 1σ band.</figcaption></figure>")
    return (f"<h2>Over temperature</h2><p class='meta'>Each term a polynomial of order {thermal['order']} in T − "
            f"{thermal['reference_c']:g} °C, T the IMU's own temperature; coefficients lowest order first, in the "
            "term's unit per °C^j.</p><table><thead><tr><th>term</th><th>coefficients</th><th>1σ</th><th>truth</th>"
            f"</tr></thead><tbody>{rows}</tbody></table>{image}")


def thermal_figure(doc: dict) -> bytes:
    """PNG: a panel per key (``block.key``) with a polynomial, two a row: each axis's term at each temperature, its
    fit and the fit's 1-sigma band."""
    plt = pyplot()
    thermal = doc["thermal"]
    points = thermal["temperatures"]
    temperatures = np.array([p["imu_c"] for p in points])
    keys = list(dict.fromkeys(name.rsplit(".", 1)[0] for name in thermal["terms"]))
    grid = np.linspace(temperatures.min() - 5.0, temperatures.max() + 5.0, 200)
    rows = (len(keys) + 1) // 2
    fig, axes = plt.subplots(rows, 2, figsize=(10, 3.4 * rows), squeeze=False)
    for ax in axes.flat[len(keys):]:
        ax.set_visible(False)
    for ax, key in zip(axes.flat, keys):
        block, name = key.split(".")
        for i, axis in enumerate("xyz"):
            if f"{key}.{i}" not in thermal["terms"]:
                continue
            values = np.array([p[block][name][i] for p in points])
            sigmas = np.array([p["sigma"][block][name][i] for p in points])
            at = term_temperatures(points, f"{key}.{i}")
            fit, band = polynomial_at(*polynomial_fit(at, values, sigmas, thermal["order"], thermal["reference_c"]),
                                      thermal["reference_c"], grid)
            line = ax.plot(grid, fit, label=axis)[0]
            ax.fill_between(grid, fit - band, fit + band, color=line.get_color(), alpha=0.25)
            ax.errorbar(at, values, yerr=sigmas, fmt="o", color=line.get_color(), ms=4)
        ax.set_title(key, fontsize=9)
        ax.set_xlabel("IMU temperature (°C)")
        ax.set_ylabel(UNITS.get(name, name))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return buf.getvalue()
