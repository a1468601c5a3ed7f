import numpy as np
import pytest
from tests.helpers import scipy_attitude

from hil.estimation.gimbal import as_stacked, gimbal_matrices, row_times
from hil.frames import TableGeometry

GEOMETRIES = [TableGeometry(), TableGeometry(0.3, (1e-3, -2e-3), (0.1, 0.2, -0.3))]


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_gimbal_matrices_equal_attitude_matrix_to_rounding(geometry):
    angles = np.random.default_rng(0).uniform(-4.0, 4.0, (5000, 3))
    c_bn, middle_inner, inner = geometry.attitude_matrix(angles)
    fast_c, fast_middle_inner = gimbal_matrices(geometry, angles)
    np.testing.assert_allclose(as_stacked(fast_c), c_bn, rtol=0, atol=1e-15)
    np.testing.assert_allclose(as_stacked(fast_middle_inner), middle_inner, rtol=0, atol=1e-15)
    np.testing.assert_allclose(fast_middle_inner[0].T, inner[:, 0, :], rtol=0, atol=1e-15)


def test_gimbal_matrices_compose_the_elementary_rotations():
    """Independent of frames.py: C_b^n = C_table^n Rz(outer) Rx(middle) Ry(inner) C_b^mount from scipy."""
    geometry = GEOMETRIES[1]
    angles = np.random.default_rng(1).uniform(-4.0, 4.0, (200, 3))
    expected = scipy_attitude(geometry, angles).as_matrix()
    np.testing.assert_allclose(as_stacked(gimbal_matrices(geometry, angles)[0]), expected, rtol=0, atol=1e-14)


def test_row_times_is_a_vector_matrix_product():
    c = np.random.default_rng(2).normal(size=(3, 3, 7))
    v = np.array([0.3, -1.2, 9.8])
    np.testing.assert_allclose(row_times(v, c).T, v @ as_stacked(c), rtol=1e-14)
