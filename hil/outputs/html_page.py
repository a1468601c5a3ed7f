"""One self-contained HTML page (inline style, figures as PNG data URIs, nothing fetched) and the parts every
report shares: the measurement table and the figures."""

from __future__ import annotations

import base64
import html

from hil.config import InputError
from hil.outputs.measurements import FAIL, PASS, Measurement

REPORT_NAME = "report.html"


class ReportError(InputError, ValueError):
    """A report that cannot be built from the directory given."""

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto; max-width: 60em;
       color: #1b1b1b; padding: 0 1em; }
h1 { margin-bottom: 0.2em; } h2 { margin-top: 1.6em; border-bottom: 1px solid #ddd; }
.meta { color: #555; }
header.run .kind { margin: 0; color: #555; text-transform: uppercase; letter-spacing: 0.06em; font-size: 0.85em; }
header.run h1 { margin-top: 0.1em; } header.run .facts b { color: #1b1b1b; font-weight: 600; }
.wide { overflow-x: auto; }
.ended { font-weight: bold; } .ended.early { color: #a40000; }
.verdict { display: inline-block; padding: 0.3em 1em; font-size: 1.6em; font-weight: bold; border-radius: 6px;
           color: white; margin: 0.5em 0; }
.verdict.PASS { background: #2e7d32; } .verdict.FAIL { background: #c62828; }
.verdict.INTERRUPTED, .verdict.ENDED.EARLY { background: #5d4037; }
table { border-collapse: collapse; width: 100%; font-size: 0.92em; }
th, td { border-bottom: 1px solid #e2e2e2; padding: 0.3em 0.6em; text-align: left; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.outcome { font-weight: bold; } td.outcome.PASS { color: #2e7d32; }
td.outcome.FAIL { color: #c62828; } td.outcome.none { color: #888; font-weight: normal; }
tr.row-FAIL { background: #fdecea; }
.note { background: #fff8e1; border-left: 4px solid #f9a825; padding: 0.4em 0.8em; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #555; font-size: 0.9em; }
@media print { .verdict { -webkit-print-color-adjust: exact; print-color-adjust: exact; } }
"""


def measurement_table(results: list[Measurement]) -> str:
    """The measurements as a table: name and description, value, unit, limit, outcome."""
    e = html.escape
    rows = []
    for m in results:
        outcome_class = m.outcome if m.outcome in (PASS, FAIL) else "none"
        rows.append(
            f"<tr class='row-{outcome_class}'><td><code>{e(m.name)}</code><br><small>{e(m.description)}</small></td>"
            f"<td class='num'>{e(m.shown)}</td><td>{e(m.unit)}</td><td class='num'>{e(m.limit)}</td>"
            f"<td class='outcome {outcome_class}'>{e(m.outcome)}</td></tr>"
        )
    return ("<table><thead><tr><th>measurement</th><th>value</th><th>unit</th><th>limit</th><th>outcome</th></tr>"
            f"</thead><tbody>{''.join(rows)}</tbody></table>")


def figures_html(figures: list[tuple[str, bytes | None]]) -> str:
    """The figures (caption, PNG; None: not drawn) as self-contained HTML."""
    return "".join(f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,"
                   f"{base64.b64encode(image).decode()}'><figcaption>{html.escape(caption)}</figcaption></figure>"
                   for caption, image in figures if image is not None)


def html_page(header: str, title: str, body: str) -> str:
    """One self-contained page: ``header`` (:func:`~hil.outputs.page_header.page_header`), inline style,
    nothing fetched."""
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{html.escape(title)}</title><style>{_CSS}</style></head>
<body>
{header}
{body}
</body></html>
"""
