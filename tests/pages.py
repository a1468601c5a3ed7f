"""What a lab sees of a page: its layout width and the table columns it cannot see, measured in headless
Chromium at a given window width (the pages are self-contained, so a file URL shows all of them)."""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium")
WINDOW_PX = 1400
needs_chromium = pytest.mark.skipif(CHROMIUM is None,
                                    reason="needs chromium (apt-get install chromium; .ci/run installs it)")

# The page measures itself once laid out: its scroll width, and the header of every table column whose right
# edge lies beyond the box that shows the table (the nearest ancestor that clips or scrolls, else the window).
_PROBE = """<script>
window.addEventListener('load', () => {
  const view = document.documentElement.clientWidth;
  const clipped = [];
  for (const table of document.querySelectorAll('table')) {
    let right = view;
    for (let box = table.parentElement; box; box = box.parentElement) {
      if (getComputedStyle(box).overflowX !== 'visible') right = Math.min(right, box.getBoundingClientRect().right);
    }
    const row = table.querySelector('tr');
    for (const cell of row ? row.children : []) {
      if (cell.getBoundingClientRect().right > right + 0.5) clipped.push(cell.textContent.trim());
    }
  }
  const found = {width: document.documentElement.scrollWidth, clipped: clipped};
  document.title = 'probe ' + btoa(unescape(encodeURIComponent(JSON.stringify(found))));
});
</script></body>"""


def measure(page: Path, tmp_path: Path, window_px: int = WINDOW_PX) -> dict:
    """``{"width": layout width in px, "clipped": [header text of each column out of sight]}`` of ``page``."""
    probe = tmp_path / f"probe-{page.parent.name}-{page.name}"
    probe.write_text(page.read_text().replace("</body>", _PROBE))
    dom = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--window-size={window_px},900",
                          "--virtual-time-budget=5000", "--dump-dom", probe.as_uri()],
                         capture_output=True, text=True, timeout=120).stdout
    start = dom.index("<title>probe ") + len("<title>probe ")
    return json.loads(base64.b64decode(dom[start:dom.index("</title>", start)]).decode())


def layout_width(page: Path, tmp_path: Path, window_px: int = WINDOW_PX) -> int:
    """The page's layout width (px) in a ``window_px`` wide window: at most ``window_px`` when nothing overflows."""
    return measure(page, tmp_path, window_px)["width"]


def clipped_columns(page: Path, tmp_path: Path, window_px: int = WINDOW_PX) -> list[str]:
    """The header text of every table column that lies beyond its table's visible box (a scrollbar hides it)."""
    return measure(page, tmp_path, window_px)["clipped"]
