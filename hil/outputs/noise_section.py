"""The noise characterisation's section of report.html: the fitted terms with their intervals."""

from __future__ import annotations

import html

from hil.outputs.measurements import format_value
from hil.outputs.noise import SENSORS

_TERM_NAMES = ("quantization", "white (random walk of the output)", "bias instability",
               "rate / acceleration random walk", "rate / acceleration ramp")
_UNITS = {"quantization_urad": "µrad", "arw_deg_per_sqrt_h": "deg/√h", "bias_instability_dph": "deg/h",
          "rrw_deg_per_h_per_sqrt_h": "deg/h/√h", "ramp_dph_per_h": "deg/h/h",
          "quantization_m_per_s": "m/s", "vrw_m_per_s_per_sqrt_h": "m/s/√h", "bias_instability_ug": "µg",
          "rrw_m_per_s2_per_sqrt_h": "m/s²/√h", "ramp_ug_per_h": "µg/h"}


def noise_section(doc: dict) -> str:
    """An HTML section of a noise.json document: per sensor and term, each axis's value and interval; a term
    not resolved says so, with its reason's number from the list under the table."""
    e = html.escape
    level = doc.get("ci", {}).get("level")
    unresolved = doc.get("unresolved", {})
    reasons = list(dict.fromkeys(unresolved.values()))
    rows = []
    for sensor, _, keys in SENSORS:
        for key, name in zip(keys, _TERM_NAMES):
            if key not in doc[sensor]:  # a noise.json written before the five terms
                continue
            values = doc[sensor][key]
            bounds = doc.get("ci", {}).get(sensor, {}).get(key, {})
            notes = [unresolved.get(f"{sensor}.{key}.{k}") for k in range(len(values))]
            cells = "".join(
                f"<td class='num'>{e(format_value(v))}"
                + ("" if v is not None else f"<br><small>not resolved{_note(note, reasons)}</small>")
                + (f"<br><small>[{e(format_value(lo))}, {e(format_value(hi))}]</small>" if hi is not None else "")
                + "</td>"
                for v, lo, hi, note in zip(values, bounds.get("lower", [None] * 3), bounds.get("upper", [None] * 3),
                                           notes))
            rows.append(f"<tr><td>{e(sensor)} {e(name)}</td>{cells}<td>{e(_UNITS[key])}</td></tr>")
    motion = ("the table's motion was taken out with its angles" if doc.get("motion_removed")
              else "a static record, analysed as it is")
    return (f"<h2>Allan deviation and noise terms</h2><p class='meta'>Overlapping Allan deviation of "
            f"{format_value(doc.get('samples'))} samples ({format_value(doc.get('duration_s'))} s, "
            f"{e(str(doc.get('source', '')))}; {motion}); terms from a joint weighted fit (IEEE Std 952 / 1293), "
            f"intervals at {format_value(level)} two-sided.</p>"
            "<table><thead><tr><th>term</th><th>x</th><th>y</th><th>z</th><th>unit</th></tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table>"
            + "".join(f"<p class='meta'>({n}) {e(reason)}</p>" for n, reason in enumerate(reasons, start=1)))


def _note(reason: str | None, reasons: list[str]) -> str:
    """The reference to a reason in the list under the table, or nothing."""
    return f" ({reasons.index(reason) + 1})" if reason in reasons else ""
