"""The header every HTML page of the project opens with (trial report, calibration, noise, campaign, history):
the page's kind and name, then when (UTC), the software, the unit, the operator and the station from the run's
record (docs/contracts.md, "result.json"), how the run ended and its verdict."""

from __future__ import annotations

import html
from typing import Any

from hil.outputs.result import COMPLETED


def page_header(kind: str, name: str, record: dict[str, Any] | None = None, ended: str | None = None,
                verdict: str | None = None) -> str:
    """The ``<header>`` of a page of ``kind`` about the run ``name``; what ``record`` lacks is left out."""
    e = html.escape
    r = record or {}
    software = " ".join(filter(None, (r.get("software_version"), f"({r['commit'][:12]})" if r.get("commit") else None)))
    unit = " ".join(filter(None, (r.get("dut_part"), r.get("dut_serial"))))
    facts = [("date (UTC)", (r.get("started_utc") or "").replace("+00:00", "")), ("software", software),
             ("unit", unit), ("operator", r.get("operator")), ("station", r.get("station"))]
    line = " · ".join(f"{e(label)} <b>{e(str(value))}</b>" for label, value in facts if value)
    state = ""
    if ended is not None:
        state = f'<p class="ended {"completed" if ended == COMPLETED else "early"}">Trial {e(ended)}.</p>'
    badge = f'<div class="verdict {e(verdict)}">{e(verdict)}</div>' if verdict else ""
    return (f'<header class="run"><p class="kind">{e(kind)}</p><h1>{e(name)}</h1>'
            f'<p class="meta facts">{line}</p>{state}{badge}</header>')
