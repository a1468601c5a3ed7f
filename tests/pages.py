"""What a lab sees of a page: its layout width and the table columns it cannot see, measured in headless
Chromium at a given window width (the pages are self-contained, so a file URL shows all of them); and the Rerun
web viewer's page, read through its own API and drawn (Playwright)."""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
import time
from pathlib import Path
from urllib.parse import urlsplit

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


# The Rerun web viewer (``--viewer serve``) in headless Chromium with software WebGL (SwiftShader, no GPU), read
# through the page's own API: once started, the page's ``window._handle`` (rerun 0.41's ``WebHandle``) encodes the
# viewer's active blueprint and recording as .rrd (``save_blueprint``, ``save_recording``) and its state as a
# ``GetViewerStateResponse`` of viewer_control.proto (``viewer_state``).
SOFTWARE_GL = ("--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader")
LOOPBACK = ("127.0.0.1", "localhost", "::1")
_ENCODED = """what => {
  let bytes;
  try { bytes = what === 'state' ? window._handle.viewer_state() : what === 'blueprint'
    ? window._handle.save_blueprint() : window._handle.save_recording(); } catch (e) { return null; }
  let text = '';
  for (let i = 0; i < bytes.length; i += 32768) text += String.fromCharCode.apply(null, bytes.subarray(i, i + 32768));
  return btoa(text);
}"""


def open_viewer(browser, url: str, window: tuple[int, int], timeout_s: float, refused: set[str] | None = None,
                errors: list[str] | None = None):
    """A page of ``browser`` (Playwright) at ``url`` in a ``window`` (width, height px), once the viewer has started
    (its WebAssembly loaded). Requests to other hosts than this one are refused (the page asks for a web font,
    release lists and its usage analytics, none of which it needs) and added to ``refused``; the page's errors
    to ``errors``."""
    page = browser.new_page(viewport={"width": window[0], "height": window[1]})

    def route(request) -> None:
        parts = urlsplit(request.request.url)
        if parts.hostname in LOOPBACK:
            request.continue_()
        else:
            request.abort()
            if refused is not None:
                refused.add(f"{parts.scheme}://{parts.hostname}")

    page.route("**/*", route)
    if errors is not None:
        page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(url)
    page.wait_for_function("window._handle !== undefined", timeout=timeout_s * 1000, polling=250)
    return page


def viewer_encoded(page, what: str) -> bytes | None:
    """The viewer's ``state``, active ``blueprint`` or ``recording`` as it encodes them; None while it has none."""
    text = page.evaluate(_ENCODED, what)
    return None if text is None else base64.b64decode(text)


def wait_for(condition, timeout_s: float, every_s: float = 1.0):
    """``condition()``'s first truthy value, asked every ``every_s``; a TimeoutError after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"{getattr(condition, '__name__', 'condition')} not met in {timeout_s:g} s")
        time.sleep(every_s)


def recorded_rows(path: Path) -> dict[str, int]:
    """The rows of each entity of the (first) recording of a .rrd, static data left out; none without a recording."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    rows: dict[str, int] = {}
    for recording in reader.recordings()[:1]:
        for chunk in reader.stream(store=recording):
            if not chunk.is_static:
                rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


def wait_for_recording(page, rrd: Path, into: Path, timeout_s: float) -> Path:
    """``into``: the viewer's active recording (.rrd) once it holds every row of ``rrd``, the one its data came from."""
    expected = recorded_rows(rrd)

    def holds_every_row() -> bool:
        encoded = viewer_encoded(page, "recording")
        if encoded is not None:
            into.write_bytes(encoded)
        return encoded is not None and recorded_rows(into) == expected

    wait_for(holds_every_row, timeout_s, every_s=2.0)
    return into


def settled_screenshot(page, window: tuple[int, int], timeout_s: float) -> bytes:
    """The page (PNG) drawn in a ``window`` (width, height px): screenshots until two in a row are the same."""
    page.set_viewport_size({"width": window[0], "height": window[1]})
    shots = [page.screenshot()]

    def settled() -> bytes | None:
        shots.append(page.screenshot())
        return shots[-1] if shots[-1] == shots[-2] else None

    return wait_for(settled, timeout_s, every_s=0.0)


def _varint(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[at]
        value, shift, at = value | (byte & 0x7F) << shift, shift + 7, at + 1
        if byte < 0x80:
            return value, at


def protobuf_fields(data: bytes) -> dict[int, list]:
    """A protobuf message's fields by number: each a list of its values, an int (varint) or bytes (a string, a
    message or fixed-width bytes)."""
    fields: dict[int, list] = {}
    at = 0
    while at < len(data):
        key, at = _varint(data, at)
        wire = key & 7
        if wire == 0:
            value, at = _varint(data, at)
        else:
            size, at = _varint(data, at) if wire == 2 else (8 if wire == 1 else 4, at)
            value, at = data[at:at + size], at + size
        fields.setdefault(key >> 3, []).append(value)
    return fields


def _one(fields: dict[int, list], number: int, default: int | bytes = b"") -> int | bytes:
    return fields.get(number, [default])[0]


def _timeline_name(fields: dict[int, list]) -> str:
    """The name of the ``Timeline`` message in field 1."""
    return _one(protobuf_fields(_one(fields, 1)), 1).decode()


def viewer_views(state: bytes) -> list[dict]:
    """The views of a ``GetViewerStateResponse`` (field 5, ``ViewerView``): name, class, origin, whether visible, and
    the summary of each warning or error it reported the last time it was drawn."""
    views = []
    for view in map(protobuf_fields, protobuf_fields(state).get(5, [])):
        views.append({"name": _one(view, 3).decode(), "class": _one(view, 2).decode(),
                      "origin": _one(view, 4).decode(), "visible": bool(_one(view, 5, 0)),
                      "reports": [_one(protobuf_fields(report), 2).decode() for report in view.get(6, [])]})
    return views


def viewer_times(state: bytes, timeline: str) -> list[tuple[int, int]]:
    """Per recording of a ``GetViewerStateResponse`` (field 3, ``ViewerRecording``) with data on ``timeline``: (its
    last time, the viewer's time cursor), in the timeline's units (ns for a duration)."""
    times = []
    for recording in map(protobuf_fields, protobuf_fields(state).get(3, [])):
        ends = {_timeline_name(entry): _one(protobuf_fields(_one(entry, 3)), 2, 0)  # time_range: start 1, end 2
                for entry in map(protobuf_fields, recording.get(2, [])) if 3 in entry}
        cursor = protobuf_fields(_one(recording, 3))  # TimeCursor: timeline 1, time 3 (its value 1)
        if cursor and _timeline_name(cursor) == timeline and timeline in ends:
            times.append((ends[timeline], _one(protobuf_fields(_one(cursor, 3)), 1, 0)))
    return times
