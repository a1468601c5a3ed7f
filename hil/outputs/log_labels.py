"""Log-axis tick labels in plain text: matplotlib's labels (10³, 2×10³, 0.5) written with Unicode
superscripts instead of mathtext, whose parser costs about 20 ms a label. Imported by the drawing code
only, after matplotlib (:func:`hil.outputs.figures.pyplot`)."""

from __future__ import annotations

import re

from matplotlib import ticker
from matplotlib.axis import Axis

_MATHTEXT = re.compile(r"^\$\\mathdefault\{(.*)\}\$$")
_POWER = re.compile(r"\^\{(-?\d+)\}")
_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def plain_text(label: str) -> str:
    """A log formatter's mathtext label as plain text: ``$\\mathdefault{2\\times10^{-3}}$`` -> ``2×10⁻³``."""
    match = _MATHTEXT.match(label)
    if match is None:
        return label
    body = match.group(1).replace(r"\times", "\u00d7")
    return _POWER.sub(lambda power: power.group(1).translate(_SUPERSCRIPT), body)


class PlainLogFormatter(ticker.LogFormatterSciNotation):
    """matplotlib's log-axis formatter, its labels in plain text (:func:`plain_text`)."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        return plain_text(super().__call__(x, pos))


def use_plain_log_labels(axis: Axis) -> None:
    """Give a log axis (``ax.xaxis`` or ``ax.yaxis``, after its scale is set) the formatters a log scale
    sets, in plain text."""
    axis.set_major_formatter(PlainLogFormatter())
    axis.set_minor_formatter(PlainLogFormatter(labelOnlyBase=False))
