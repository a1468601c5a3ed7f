"""PNG figures in the style of the 2019 paper: Fig. 2 (Gram rank), Fig. 3 (bias), Fig. 4 (alignment).

matplotlib is imported when figures are drawn, not with this module.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from hil.outputs.series import SERIES_COLUMNS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIGURES = ("observability.png", "bias.png", "alignment.png")
Draw = Callable[[Path, np.ndarray, dict], None]  # draws a trial's figures: write_figures, FigureProcess.draw


def _col(series: np.ndarray, name: str) -> np.ndarray:
    return series[:, SERIES_COLUMNS.index(name)]


def write_figures(out: Path, series: np.ndarray, result: dict, names: tuple[str, ...] = FIGURES) -> None:
    """Draw the figures ``names`` (of :data:`FIGURES`) of a trial's series into ``out``."""
    plt = pyplot()
    for name in names:
        fig = _DRAWERS[name](plt, series, result)
        fig.savefig(out / name, dpi=100)
        plt.close(fig)


def pyplot() -> ModuleType:
    """matplotlib's pyplot on the Agg backend (files only, no display), imported on first use."""
    import matplotlib  # 0.4 s: only for a trial that draws (docs/architecture.md, the figure process)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _observability(plt: ModuleType, series: np.ndarray, result: dict) -> Figure:
    from hil.outputs.log_labels import use_plain_log_labels  # with matplotlib, which pyplot() has imported

    t = _col(series, "t_s")
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    ax1.step(t, _col(series, "gram_rank"), where="post", label="12-state")
    ax1.step(t, _col(series, "gram_rank_9"), where="post", label="9-state", linestyle="--")
    ax1.set_ylabel("rank of scaled Gram matrix")
    ax1.legend()
    ax2.semilogy(t, _col(series, "gram_condition"))
    use_plain_log_labels(ax2.yaxis)
    ax2.set_ylabel("condition number")
    ax2.set_xlabel("time (s)")
    fig.suptitle("Observability (cf. Liu 2019 Fig. 2)")
    return fig


def _bias(plt: ModuleType, series: np.ndarray, result: dict) -> Figure:
    t = _col(series, "t_s")
    truth = (result.get("truth") or {}).get("accel_bias_ug")
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for k, (ax, axis) in enumerate(zip(axes, "xyz")):
        b, s = _col(series, f"bias_{axis}_ug"), _col(series, f"sigma_{axis}_ug")
        ax.plot(t, b, label="estimate")
        ax.fill_between(t, b - 3 * s, b + 3 * s, alpha=0.3, label="+-3 sigma")
        if truth is not None:
            ax.axhline(truth[k], color="k", linestyle=":", label="truth")
        ax.set_ylabel(f"bias {axis} (ug)")
        finite = b[np.isfinite(b)]
        if finite.size:
            centre, spread = finite[-1], max(np.ptp(finite[len(finite) // 4 :]), 5.0)
            ax.set_ylim(centre - 2 * spread, centre + 2 * spread)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("Accelerometer bias (cf. Liu 2019 Fig. 3)")
    return fig


def _alignment(plt: ModuleType, series: np.ndarray, result: dict) -> Figure:
    t = _col(series, "t_s")
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for ax, angle in zip(axes, ("pitch", "roll", "yaw")):
        ax.plot(t, _col(series, f"method1_{angle}_deg"), "--", label="method 1")
        ax.plot(t, _col(series, f"method2_{angle}_deg"), label="method 2")
        if angle != "yaw":
            ax.plot(t, _col(series, f"theoretical_{angle}_deg"), ":", label="theoretical")
        ax.axhline(0.0, color="k", linewidth=0.5)
        ax.set_ylabel(f"{angle} error (deg)")
        tail = _col(series, f"method1_{angle}_deg")[len(t) // 10 :]
        tail = tail[np.isfinite(tail)]
        if tail.size:
            lim = 3 * max(np.max(np.abs(tail)), 1e-4)
            ax.set_ylim(-lim, lim)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("Alignment error against the turntable (cf. Liu 2019 Fig. 4)")
    return fig


_DRAWERS = dict(zip(FIGURES, (_observability, _bias, _alignment)))
