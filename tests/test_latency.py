"""drivers.latency: the bounded latency histogram the emulator's writers (and the harness) keep."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.latency import LatencyHistogram


def test_an_empty_histogram_has_no_percentiles_and_no_maximum():
    h = LatencyHistogram()
    assert h.count == 0 and h.percentile_ms(50) is None and h.max_ms() is None


def test_percentiles_read_the_upper_edge_of_their_bin_and_the_maximum_is_exact():
    h = LatencyHistogram()  # 10 us bins
    for ms in (0.105, 0.205, 0.305, 0.405):
        h.add(ms * 1e-3)
    assert h.count == 4
    assert h.percentile_ms(50) == 0.21 and h.percentile_ms(99) == 0.41
    assert h.max_ms() == pytest.approx(0.405)


def test_values_beyond_the_range_land_in_the_end_bins_but_keep_their_maximum():
    h = LatencyHistogram(bin_s=1e-3, bins=10)
    h.add(-0.5)
    h.add(5.0)
    assert h.percentile_ms(1) == 1.0 and h.percentile_ms(100) == 10.0
    assert h.max_ms() == pytest.approx(5000.0)
    assert int(h.counts.sum()) == 2 and len(h.counts) == 10


def test_a_histogram_needs_positive_bins():
    with pytest.raises(ValueError):
        LatencyHistogram(bin_s=0.0)


def test_percentiles_at_once_are_the_percentiles_one_by_one():
    h = LatencyHistogram()
    for k in range(1000):
        h.add((k + 0.5) * 1e-5)  # one value in each 10 us bin up to 10 ms
    assert h.count == 1000
    # the 500th value is in bin 499, whose upper edge is 5.00 ms; the 990th in bin 989 (9.90 ms)
    assert h.percentiles_ms([50, 99]) == [h.percentile_ms(50), h.percentile_ms(99)] == [5.0, 9.9]


def test_percentiles_equal_the_bin_of_the_sorted_values_in_a_wide_histogram():
    rng = np.random.default_rng(7)
    values = rng.gamma(2.0, 2e-3, 5000)  # a few ms, in a histogram reaching 1 s
    h = LatencyHistogram(bins=100_000)
    for v in values:
        h.add(float(v))
    ordered = np.sort(values)
    for q in (1, 50, 99, 100):
        kth = ordered[int(np.ceil(q / 100 * len(values))) - 1]  # the value the q-th percentile falls on
        assert h.percentile_ms(q) == round((int(kth / 1e-5) + 1) * 1e-2, 3)
