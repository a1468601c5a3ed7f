import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view

from hil.estimation.outlier_gate import accepted, sliding_extreme

WINDOW, SIGMAS, FLOOR = 25, 10.0, 5e-3


def sliding_median_gate(series: np.ndarray, window: int, sigmas: float, floor: float) -> np.ndarray:
    """The gate's definition: the median and MAD of every full window, by partition over all of them."""
    windows = sliding_window_view(series[:-1], window, axis=0)
    centre = np.median(windows, axis=-1)
    spread = 1.4826 * np.median(np.abs(windows - centre[..., None]), axis=-1)
    limit = np.maximum(sigmas * spread, floor)
    return np.all(np.abs(series[window:] - centre) <= limit, axis=1)


@pytest.mark.parametrize("noise", [5e-4, 2e-3, 1e-2])  # quiet (floor decides), near the floor, noisy (MAD decides)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gate_decides_as_the_sliding_median_on_random_data_with_outliers(noise, seed):
    rng = np.random.default_rng(seed)
    n = 20_000
    series = np.array([0.1, -0.2, 9.8]) + noise * rng.standard_normal((n, 3))
    hit = rng.choice(n, 200, replace=False)
    series[hit, rng.integers(0, 3, 200)] += rng.choice([-1.0, 1.0], 200) * rng.uniform(1e-3, 0.5, 200)
    series[rng.choice(n, 5)] = np.nan
    expected = sliding_median_gate(series, WINDOW, SIGMAS, FLOOR)
    got = accepted(series, WINDOW, SIGMAS, FLOOR)
    assert (~expected).sum() > 0
    np.testing.assert_array_equal(got, expected)


def test_gate_decides_as_the_sliding_median_on_the_edge_of_the_floor():
    """Steps of exactly the floor and ties: the decisions are those of the definition."""
    rng = np.random.default_rng(4)
    series = rng.integers(-3, 4, (5000, 3)) * (FLOOR / 2)
    np.testing.assert_array_equal(accepted(series, WINDOW, SIGMAS, FLOOR),
                                  sliding_median_gate(series, WINDOW, SIGMAS, FLOOR))


@pytest.mark.parametrize("window", [1, 2, 7, 25, 32])
def test_sliding_extreme_is_the_extreme_of_every_window(window):
    x = np.random.default_rng(5).standard_normal((300, 3))
    windows = sliding_window_view(x, window, axis=0)
    np.testing.assert_array_equal(sliding_extreme(np.minimum, x, window), windows.min(axis=-1))
    np.testing.assert_array_equal(sliding_extreme(np.maximum, x, window), windows.max(axis=-1))
