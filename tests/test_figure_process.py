"""The figure process: the child draws what this process would, and a failing child loses nothing."""

import os
import time

import numpy as np

from hil.outputs.figure_process import NICENESS, FigureProcess, _hand_over
from hil.outputs.figures import FIGURES, write_figures
from hil.outputs.series import SERIES_COLUMNS

RESULT = {"truth": {"accel_bias_ug": [60.0, 150.0, 260.0]}}


def _series() -> np.ndarray:
    rng = np.random.default_rng(3)
    series = rng.normal(size=(50, len(SERIES_COLUMNS)))
    series[:, SERIES_COLUMNS.index("t_s")] = np.arange(50.0)
    series[:, SERIES_COLUMNS.index("gram_condition")] = 1.0 + np.arange(50.0)
    series[:5, SERIES_COLUMNS.index("bias_x_ug")] = np.nan  # before the bias is observable
    return series


def test_the_child_draws_the_figures_this_process_draws(tmp_path):
    (tmp_path / "here").mkdir()
    (tmp_path / "child").mkdir()
    write_figures(tmp_path / "here", _series(), RESULT)
    with FigureProcess() as figures:
        figures.draw(tmp_path / "child", _series(), RESULT)
    for name in FIGURES:
        assert (tmp_path / "child" / name).read_bytes() == (tmp_path / "here" / name).read_bytes()


def test_a_child_that_is_gone_leaves_the_drawing_to_this_process(tmp_path, capsys):
    with FigureProcess() as figures:
        figures._child.kill()
        figures._child.wait()
        figures.draw(tmp_path, _series(), RESULT)
    assert all((tmp_path / name).stat().st_size > 0 for name in FIGURES)
    err = capsys.readouterr().err
    assert err.startswith("hil: the figure process failed (") and err.count("\n") == 1


def test_a_child_whose_drawing_fails_names_the_reason(tmp_path):
    out = tmp_path / "not-a-directory"
    out.write_text("")  # the child cannot write its PNGs here
    with FigureProcess() as figures:
        child, figures._child = figures._child, None
        reason = _hand_over(child, out, _series(), RESULT)
    assert child.returncode != 0 and "not-a-directory" in reason


def test_a_figure_the_childs_fork_fails_to_draw_fails_the_child(tmp_path):
    (tmp_path / FIGURES[0]).mkdir()  # the fork cannot write the first figure; the child writes the others
    with FigureProcess() as figures:
        child, figures._child = figures._child, None
        reason = _hand_over(child, tmp_path, _series(), RESULT)
    assert child.returncode != 0 and f"drawing {FIGURES[0]} failed" in reason
    assert all((tmp_path / name).stat().st_size > 0 for name in FIGURES[1:])


def test_a_child_given_no_job_ends_when_closed():
    figures = FigureProcess()
    child = figures._child
    figures.close()
    assert child.returncode is not None and child.stdin.closed


def test_the_child_runs_nicer_than_this_process():
    mine = os.getpriority(os.PRIO_PROCESS, 0)
    with FigureProcess() as figures:
        deadline = time.monotonic() + 10.0
        while os.getpriority(os.PRIO_PROCESS, figures._child.pid) == mine and time.monotonic() < deadline:
            time.sleep(0.01)
        assert os.getpriority(os.PRIO_PROCESS, figures._child.pid) == min(mine + NICENESS, 19)
