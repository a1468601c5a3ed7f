"""The 3-D scene of a trial: the turntable's three gimbals with the IMU case, and the reconstructed
apparent-gravity cone in i_b0."""

from __future__ import annotations

import numpy as np
import rerun as rr

from hil.frames import EARTH_RATE, TableGeometry
from hil.viewer.blueprint import TRUTH_COLOR

CONE_POINTS = 72
CONE_LENGTH = 1.5  # scene units (the outer gimbal has radius 1)
GIMBALS = (("world/table/outer", 0, 2), ("world/table/outer/middle", 1, 0), ("world/table/outer/middle/inner", 2, 1))


def circle(radius: float, plane: str, n: int = 64) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, n + 1)
    c, s = radius * np.cos(a), radius * np.sin(a)
    z = np.zeros_like(a)
    return {"xy": np.column_stack((c, s, z)), "xz": np.column_stack((c, z, s)), "yz": np.column_stack((z, c, s))}[plane]


def axis_quaternions(angles: np.ndarray, axis: int) -> np.ndarray:
    """Quaternions (x, y, z, w) of rotations by ``angles`` about one coordinate axis, (N, 4)."""
    q = np.zeros((len(angles), 4))
    q[:, axis] = np.sin(0.5 * angles)
    q[:, 3] = np.cos(0.5 * angles)
    return q


def cone_strips(solution, t: float, points: int = CONE_POINTS) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The reconstructed apparent-gravity cone in i_b0 (2014 eq. 17), unit length ``CONE_LENGTH``.

    Returns the wireframe of one sidereal day of the model (rim and generatrices), the arc swept
    during the trial so far, and the vector at ``t``.
    """
    day = 2.0 * np.pi / EARTH_RATE
    f = solution.apparent_gravity(np.linspace(0.0, day, points + 1))
    scale = CONE_LENGTH / np.linalg.norm(f[0])
    rim = f * scale
    generatrices = [np.vstack((np.zeros(3), rim[k])) for k in range(0, points, points // 8)]
    arc = solution.apparent_gravity(np.linspace(0.0, max(t, 0.0), 32)) * scale
    return [rim, *generatrices], arc, arc[-1]


def log_turntable(rec: rr.RecordingStream, geometry: TableGeometry) -> None:
    """The base, three gimbal rings with their axles, the IMU case on the inner gimbal (static)."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("world/table", rr.Transform3D(mat3x3=geometry.table_to_n_matrix), static=True)
    rec.log("world/table/base", rr.Boxes3D(centers=[0, 0, -1.28], half_sizes=[0.7, 0.7, 0.06],
                                           colors=(90, 90, 90), fill_mode="solid"), static=True)  # fmt: skip
    rec.log("world/table/shaft", rr.LineStrips3D([[[0, 0, -1.22], [0, 0, -1.0]]], radii=0.03, colors=(150, 150, 150)),
            static=True)  # fmt: skip
    for path, strips, color in (
        ("world/table/outer/ring", [circle(1.0, "xz")], (55, 126, 184)),
        ("world/table/outer/middle/ring", [circle(0.8, "xy"), [[0.8, 0, 0], [1.0, 0, 0]], [[-0.8, 0, 0], [-1.0, 0, 0]]],
         (77, 175, 74)),
        ("world/table/outer/middle/inner/ring", [circle(0.6, "yz"), [[0, 0.6, 0], [0, 0.8, 0]], [[0, -0.6, 0], [0, -0.8, 0]]],
         (228, 26, 28)),
    ):  # fmt: skip
        rec.log(path, rr.LineStrips3D(strips, radii=0.02, colors=color), static=True)
    imu = "world/table/outer/middle/inner/imu"
    rec.log(imu, rr.Transform3D(mat3x3=geometry.body_to_mount_matrix), rr.TransformAxes3D(0.45),
            static=True)  # fmt: skip
    rec.log(f"{imu}/case", rr.Boxes3D(half_sizes=[0.22, 0.18, 0.1], colors=(200, 200, 200), fill_mode="solid",
                                     labels="IMU"), static=True)  # fmt: skip


def log_cone(rec: rr.RecordingStream, solution, t: float) -> None:
    """The reconstructed cone, the arc swept so far and the apparent gravity now, at trial time ``t``."""
    wireframe, arc, now = cone_strips(solution, t)
    rec.set_time("trial_time", duration=t)
    rec.log("world/ib0/cone", rr.LineStrips3D(wireframe, radii=0.004, colors=(120, 120, 160)))
    rec.log("world/ib0/trial_arc", rr.LineStrips3D([arc], radii=0.015, colors=TRUTH_COLOR))
    rec.log("world/ib0/apparent_gravity", rr.Arrows3D(vectors=[now], radii=0.012, colors=(240, 240, 240)))
