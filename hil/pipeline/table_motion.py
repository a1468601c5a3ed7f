"""What the table's motion and the earth make an ideal IMU sense, taken out of its increments, so that a
noise analysis of a moving trial sees the sensor's errors only."""

from __future__ import annotations

import numpy as np

from hil.frames import Earth, TableGeometry, table_body_rotation
from hil.pipeline.plausibility import small_rotation_vectors
from hil.samples import AlignedBatch


def motion_residuals(batch: AlignedBatch, geometry: TableGeometry, earth: Earth) -> tuple[np.ndarray, np.ndarray]:
    """(dtheta, dv) of samples 1..N-1 minus the ideal increments the table angles give.

    Gyro: the body's rotation in inertial space over each interval (earth rate and gimbal motion, from
    the angles at both ends: :func:`hil.frames.table_body_rotation`) as a rotation vector. Accelerometer:
    the normal gravity's specific force in the body at the interval's middle, times its length (the
    centripetal and sculling terms of a swing, below 1e-6 of g per sample at the paper's motion, are
    left in). The first sample has no angles at its interval's start and is dropped.
    """
    if batch.angles is None:
        raise ValueError("the table's motion can be taken out only with its angles")
    t, angles = batch.t, np.unwrap(batch.angles, axis=0)
    dt = np.diff(t)
    rotation = table_body_rotation(geometry, earth, dt, angles[:-1], angles[1:])
    dtheta = batch.dtheta[1:] - small_rotation_vectors(rotation)
    c_bn = geometry.attitude_matrix(0.5 * (angles[:-1] + angles[1:]))[0]
    dv = batch.dv[1:] - (earth.f_n @ c_bn) * dt[:, None]
    return dtheta, dv
