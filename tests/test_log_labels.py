import numpy as np
import pytest

from hil.outputs.figures import pyplot

pyplot()  # the Agg backend before matplotlib's ticker is imported by the module under test
from hil.outputs.log_labels import plain_text, use_plain_log_labels  # noqa: E402


@pytest.mark.parametrize("mathtext, plain", [
    (r"$\mathdefault{10^{3}}$", "10\u00b3"),
    (r"$\mathdefault{10^{-12}}$", "10\u207b\u00b9\u00b2"),
    (r"$\mathdefault{2\times10^{5}}$", "2\u00d710\u2075"),
    (r"$\mathdefault{0.5}$", "0.5"),
    ("", ""),
    ("plain", "plain"),
])
def test_mathtext_labels_become_plain_text(mathtext, plain):
    assert plain_text(mathtext) == plain


@pytest.mark.parametrize("limits", [(1e3, 2e6), (1e-9, 1e-2), (2e3, 8e3)])  # wide ranges, and under a decade
def test_a_plain_log_axis_labels_the_ticks_matplotlib_labels(limits):
    """Same ticks labelled as by matplotlib's own log formatter, with no mathtext left."""
    plt = pyplot()
    labels = []
    for plain in (False, True):
        fig, ax = plt.subplots()
        ax.semilogy([0, 1], limits)
        if plain:
            use_plain_log_labels(ax.yaxis)
        fig.canvas.draw()
        labels.append([[t.get_text() for t in ticks] for ticks in (ax.get_yticklabels(), ax.get_yticklabels(minor=True))])
        plt.close(fig)
    default, plain = labels
    assert [[plain_text(s) for s in ticks] for ticks in default] == plain
    assert any(any(ticks) for ticks in plain) and not any("$" in s for ticks in plain for s in ticks)
