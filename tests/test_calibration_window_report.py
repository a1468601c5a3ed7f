"""A calibration window is shown live once samples past its end arrive; when the data end at its end (the last
window of a trial stopped as the table finished), :meth:`CalibrationSequence.report_rest` shows it from the
samples that came, as the fit takes it."""

from __future__ import annotations

import numpy as np

from hil.estimation.calibration_schedule import default_schedule
from hil.trial.calibration_sequence import CalibrationSequence, StepWindow

PERIOD = 0.005


def _sequence(reported: list) -> CalibrationSequence:
    schedule = default_schedule(positions=6, dwell_s=2.0)
    sequence = CalibrationSequence(schedule, client=None, sample_period=PERIOD,
                                   on_window=lambda t, index, window: reported.append((t, index)))
    sequence.windows_found = [StepWindow(sequence.steps[0], 1.0, 3.0)]
    return sequence


def _keep(sequence: CalibrationSequence, t: np.ndarray) -> None:
    n = len(t)
    dv = np.tile([0.0, 0.0, 9.8 * PERIOD], (n, 1))
    sequence.keep(t, np.zeros((n, 3)), dv, np.zeros((n, 3)))


def test_a_window_whose_data_end_before_its_end_is_shown_at_the_end_of_data_and_only_once():
    reported: list = []
    sequence = _sequence(reported)
    _keep(sequence, np.arange(1, 600) * PERIOD)  # the last sample 2.995 s: short of the window's end
    assert reported == []
    sequence.report_rest()
    sequence.report_rest()
    assert reported == [(3.0, 0)] and sequence.failure is None


def test_a_window_is_shown_as_soon_as_a_sample_past_its_end_arrives():
    reported: list = []
    sequence = _sequence(reported)
    _keep(sequence, np.arange(1, 700) * PERIOD)
    assert reported == [(3.0, 0)]
    sequence.report_rest()
    assert reported == [(3.0, 0)]


def test_at_the_end_of_data_a_window_lacking_samples_is_left_to_the_fit_and_ends_nothing():
    reported: list = []
    sequence = _sequence(reported)
    _keep(sequence, np.arange(1, 300) * PERIOD)  # half the window
    sequence.report_rest()
    assert reported == [] and sequence.failure is None
