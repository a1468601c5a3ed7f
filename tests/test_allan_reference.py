"""The Allan deviation against NIST SP 1065's 1000-point reference data set and an independent OADEV, on
every tau grid."""

from __future__ import annotations

import numpy as np
import pytest

from hil.estimation import allan
from hil.estimation.allan_taus import decade_factors, listed_factors, parse_taus, tau_factors

# NIST SP 1065 section 12.4: n_0 = 1 234 567 890, n_{i+1} = 16807 n_i mod (2^31 - 1), the frequency data
# n_i / (2^31 - 1) for i = 0..999 at tau_0 = 1 s; Table 31 gives the overlapping ADEV at 1, 10 and 100 s.
MODULUS = 2**31 - 1
PUBLISHED_OADEV = {1: 2.922319e-01, 10: 9.159953e-02, 100: 3.241343e-02}


def nbs14_frequency() -> np.ndarray:
    values, n = [], 1_234_567_890
    for _ in range(1000):
        values.append(n / MODULUS)
        n = 16807 * n % MODULUS
    return np.array(values)


def plain_oadev(y: np.ndarray, m: int) -> float:
    """Overlapping ADEV straight from frequency data: averages of m values at every start, differences of
    averages m apart, half their mean square (SP 1065 Eq. 13), with no phase and no running sums."""
    averages = np.convolve(y, np.ones(m) / m, mode="valid")
    differences = averages[m:] - averages[:-m]
    return float(np.sqrt(0.5 * np.mean(differences**2)))


def test_the_generator_gives_the_published_first_values():
    n1 = 16807 * 1_234_567_890 % MODULUS
    assert n1 == 395_529_916
    assert 16807 * n1 % MODULUS == 1_209_410_747


def test_nbs14_oadev_at_1_10_100_s_matches_nist_sp1065():
    y = nbs14_frequency()
    result = allan.analyse(y, 1.0, taus=(1.0, 10.0, 100.0))  # frequency times 1 s: the increments
    assert list(result.tau) == [1.0, 10.0, 100.0]
    for k, tau in enumerate((1, 10, 100)):
        assert result.adev[k, 0] == pytest.approx(PUBLISHED_OADEV[tau], rel=1e-4)
        assert plain_oadev(y, tau) == pytest.approx(PUBLISHED_OADEV[tau], rel=1e-4)


@pytest.mark.parametrize("grid", ["octave", "decade", "all", (1.0, 3.0, 10.0, 30.0, 100.0, 300.0)])
def test_nbs14_every_grid_matches_an_independent_oadev_at_every_tau(grid):
    y = nbs14_frequency()
    result = allan.analyse(y, 1.0, taus=grid)
    expected = [plain_oadev(y, int(m)) for m in result.tau]
    np.testing.assert_allclose(result.adev[:, 0], expected, rtol=1e-10)
    assert np.all((result.lower[:, 0] < result.adev[:, 0]) & (result.adev[:, 0] < result.upper[:, 0]))


def test_the_grids_have_the_taus_labs_use():
    assert list(tau_factors("octave", 1000, 1.0)) == [1, 2, 4, 8, 16, 32, 64, 128, 256]
    assert list(decade_factors(1000, 1.0)) == [1, 2, 5, 10, 20, 50, 100, 200, 500]
    assert list(decade_factors(2_880_000, 0.01)) == [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10_000,
                                                     20_000, 50_000, 100_000, 200_000, 500_000, 1_000_000]
    assert list(decade_factors(100_000, 0.005)) == [1, 2, 4, 10, 20, 40, 100, 200, 400, 1000, 2000, 4000, 10_000,
                                                    20_000, 40_000]  # 200 Hz: 0.005 s, 0.01 s, 0.02 s, 0.05 s, ...
    # 5 ms, 10 ms, 20 ms ... as the nearest multiples of 3 ms
    assert list(decade_factors(1000, 0.003)) == [2, 3, 7, 17, 33, 67, 167, 333]
    assert list(tau_factors("all", 9, 1.0)) == [1, 2, 3, 4]
    assert list(listed_factors((1.0, 3600.0, 10.0), 1_000_000, 0.01)) == [100, 1000, 360_000]


def test_bad_tau_lists_are_one_clear_error():
    assert parse_taus("decade") == "decade" and parse_taus("1,10,3600") == (1.0, 10.0, 3600.0)
    with pytest.raises(ValueError, match="expected octave, decade, all or taus in s"):
        parse_taus("weekly")
    with pytest.raises(ValueError, match="positive"):
        parse_taus("1,-10")
    with pytest.raises(ValueError, match="not a multiple of the sample period 0.01 s"):
        listed_factors((0.015,), 1000, 0.01)
    with pytest.raises(ValueError, match="longer than half the record"):
        listed_factors((6.0,), 1000, 0.01)
