import numpy as np
import pytest

from hil.estimation.gimbal import attitude_matrices
from hil.frames import TableGeometry


@pytest.mark.parametrize("geometry", [TableGeometry(), TableGeometry(0.3, (1e-3, -2e-3), (0.1, 0.2, -0.3))])
def test_attitude_matrices_equal_attitude_matrix_to_the_bit(geometry):
    angles = np.random.default_rng(0).uniform(-4.0, 4.0, (5000, 3))
    c_bn, middle_inner, inner = geometry.attitude_matrix(angles)
    fast_c, fast_middle_inner = attitude_matrices(geometry, angles)
    np.testing.assert_array_equal(fast_c, c_bn)
    np.testing.assert_array_equal(fast_middle_inner, middle_inner)
    np.testing.assert_array_equal(fast_middle_inner[:, 0, :], inner[:, 0, :])
