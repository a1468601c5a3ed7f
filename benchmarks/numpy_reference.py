"""`hil simulate configs/liu2019_sim.yaml` beside a plain numpy implementation of the same scenario.

The reference is the 2019 paper's scenario written as a newcomer with numpy would write it from the papers,
in one file and without the project: the swing's truth (gimbal angles and rates, body rate, specific force)
and the sensor errors for all 400 000 samples at once as arrays, then the estimator as the papers state
its recursions, one sample at a time: the attitude update in i_b0 (rotation vector, Rodrigues), the
measured specific force resolved in i_b0, the 12-state regressor (2019 eqs. 9-15) added to the normal
equations; a solve with its sigma (residual variance) and the dual-vector alignment (2014 eqs. 7-9) every
5 s, as the config's ``estimator.solve_rate_hz``. Its estimate is printed beside the truth to show it is the
same computation (its first-order increments, which take the rate as constant over an interval, leave a few
micro-g of bias at 100 Hz, falling as the square of the interval; the project fits quadratics over three
increments for this). "lean" is the same with every step that does not need the attitude taken for all
samples at once, leaving two 3x3 products a sample in the loop: what numpy allows at best without compiling. Both are timed as whole processes (best of ``--repeat``) and the ratio printed.

    .venv/bin/python benchmarks/numpy_reference.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "liu2019_sim.yaml"
UG, DEG, DPH = 9.80665e-6, np.pi / 180.0, np.pi / 180.0 / 3600.0
EARTH_RATE = 7.2921151467e-5

# configs/liu2019_sim.yaml (the paper's Tables 1 and 2), repeated here so the reference stands alone
DURATION, RATE, LATITUDE = 4000.0, 100.0, 32.0 * DEG
AMPLITUDE = np.array([8.0, 6.0, 13.0]) * DEG  # outer (yaw), middle (pitch), inner (roll)
PERIOD = np.array([8.0, 10.0, 8.0])
CENTER = np.array([5.0, 2.0, 6.0]) * DEG
ACCEL_BIAS, ACCEL_NOISE = np.array([60.0, 150.0, 260.0]) * UG, 50.0 * UG
GYRO_BIAS, GYRO_NOISE = 0.01 * DPH, 0.01 * DPH
SOLVE_EVERY = 500  # samples: 5 s


def rot(axis: int, a: np.ndarray) -> np.ndarray:
    """Elementary rotations (N, 3, 3) about x (0), y (1) or z (2), body to parent."""
    c, s = np.cos(a), np.sin(a)
    m = np.zeros((len(a), 3, 3))
    i, j = [k for k in range(3) if k != axis]
    m[:, axis, axis] = 1.0
    m[:, i, i], m[:, j, j] = c, c
    m[:, i, j], m[:, j, i] = -s, s
    if axis == 1:
        m[:, i, j], m[:, j, i] = s, -s
    return m


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def expm_so3(v: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for the rotation vector v."""
    a = np.linalg.norm(v)
    k = skew(v)
    if a < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + np.sin(a) / a * k + (1.0 - np.cos(a)) / a**2 * (k @ k)


def rodrigues(v: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for rotation vectors (N, 3) at once."""
    a = np.linalg.norm(v, axis=1)[:, None, None]
    small, safe = a < 1e-6, np.where(a < 1e-6, 1.0, a)
    k = np.zeros((len(v), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    k -= k.transpose(0, 2, 1)
    sinc = np.where(small, 1.0 - a**2 / 6.0, np.sin(safe) / safe)
    cosc = np.where(small, 0.5 - a**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + sinc * k + cosc * (k @ k)


def rotation_vectors(r: np.ndarray) -> np.ndarray:
    """The rotation vectors (N, 3) of small rotations (N, 3, 3), the inverse of Rodrigues' formula."""
    v = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], axis=1)
    s = 0.5 * np.linalg.norm(v, axis=1)
    angle = np.arctan2(s, 0.5 * (np.trace(r, axis1=1, axis2=2) - 1.0))
    return v * (0.5 * angle / np.where(s > 0, s, 1.0) + 0.5 * (s == 0))[:, None]


def triad(a1: np.ndarray, a2: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> np.ndarray:
    """The rotation C with C a1 || b1 and C (a1 x a2) || b1 x b2 (the dual-vector construction)."""

    def frame(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        w = np.cross(u, v)
        return np.column_stack([u / np.linalg.norm(u), w / np.linalg.norm(w), np.cross(u, w) / np.linalg.norm(np.cross(u, w))])

    return frame(b1, b2) @ frame(a1, a2).T


def attitudes(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gimbal attitudes C_b^n (N, 3, 3) at the times t, and the body rate relative to n (N, 3)."""
    arg = np.outer(t, 2.0 * np.pi / PERIOD)
    angles, rates = AMPLITUDE * np.sin(arg) + CENTER, AMPLITUDE * (2.0 * np.pi / PERIOD) * np.cos(arg)
    rz, rx, ry = rot(2, angles[:, 0]), rot(0, angles[:, 1]), rot(1, angles[:, 2])
    zero = np.zeros(len(t))
    w_nb = (np.einsum("nji,nkj,nk->ni", ry, rx, np.column_stack([zero, zero, rates[:, 0]]))
            + np.einsum("nji,nj->ni", ry, np.column_stack([rates[:, 1], zero, zero])) + np.column_stack([zero, rates[:, 2], zero]))
    return rz @ rx @ ry, w_nb


def truth(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Interval start times, measured increments (dtheta, dv) and the true C_b^n at each interval's end.

    The angle increment is the rotation between the true inertial attitudes at the interval's ends (so
    the integrated attitude is exact but for the sensor errors); the velocity increment is the body-frame
    specific force at the interval's middle times the interval."""
    dt = 1.0 / RATE
    edges = np.arange(int(DURATION * RATE) + 1) * dt
    axis = np.array([0.0, np.cos(LATITUDE), np.sin(LATITUDE)])
    c_bn, _ = attitudes(edges)
    c_bi = rodrigues(np.outer(EARTH_RATE * edges, axis)) @ c_bn
    dtheta = rotation_vectors(np.einsum("nji,njk->nik", c_bi[:-1], c_bi[1:]))
    c_mid, _ = attitudes(edges[:-1] + 0.5 * dt)
    g = 9.7803253359 * (1 + 0.00193185265241 * np.sin(LATITUDE) ** 2) / np.sqrt(1 - 0.00669437999013 * np.sin(LATITUDE) ** 2)
    f_b = np.einsum("nji,j->ni", c_mid, np.array([0.0, 0.0, g]))
    rng = np.random.default_rng(seed)
    dtheta += (GYRO_BIAS + GYRO_NOISE * rng.standard_normal(dtheta.shape)) * dt
    dv = (f_b + ACCEL_BIAS + ACCEL_NOISE * rng.standard_normal(f_b.shape)) * dt
    return edges[:-1], dtheta, dv, c_bn[1:]


def estimate(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, c_bn: np.ndarray,
             lean: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """The papers' recursions sample by sample; returns the last bias, its sigma and level alignment error (rad).

    ``lean``: the rotations and the sculling terms of all samples formed at once beforehand, so that the loop
    holds only the attitude recursion (two 3x3 products a sample)."""
    dt = 1.0 / RATE
    axis = np.array([0.0, np.cos(LATITUDE), np.sin(LATITUDE)])
    g_n = np.array([0.0, 0.0, 1.0])
    c = np.eye(3)  # C_b^ib0
    w, r, zz = np.zeros((12, 12)), np.zeros(12), 0.0
    z, mean_c = np.empty((SOLVE_EVERY, 3)), np.empty((SOLVE_EVERY, 3, 3))
    if lean:  # what does not depend on the attitude, for all samples at once
        sculled = np.einsum("nij,nj->ni", rodrigues(0.5 * dtheta), dv) / dt
        rotations = rodrigues(dtheta)
    for k in range(len(t)):
        i = k % SOLVE_EVERY
        if lean:
            z[i] = c @ sculled[k]
            new = c @ rotations[k]
        else:
            z[i] = c @ expm_so3(0.5 * dtheta[k]) @ dv[k] / dt  # mean specific force in i_b0
            new = c @ expm_so3(dtheta[k])
        mean_c[i] = 0.5 * (c + new)
        c = new
        if i == SOLVE_EVERY - 1:  # the block's rows into the normal equations, then a solve
            wt = EARTH_RATE * (t[k - i:k + 1] + 0.5 * dt)
            basis = np.column_stack([1.0 - np.cos(wt), np.sin(wt), np.ones_like(wt)])
            h = np.concatenate([np.einsum("nb,ij->nibj", basis, np.eye(3)).reshape(-1, 3, 9), mean_c], axis=2)
            w += np.einsum("nia,nib->ab", h, h)
            r += np.einsum("nia,ni->a", h, z)
            zz += np.sum(z * z)
            n = 3 * (k + 1)
            x = np.linalg.solve(w, r)
            s2 = (zz - 2.0 * x @ r + x @ w @ x) / (n - 12)
            sigma = np.sqrt(s2 * np.diag(np.linalg.inv(w))[9:])
            a = x[:9].reshape(3, 3)
            tk = t[k] + dt
            gravity = [a.T @ np.array([1.0 - np.cos(EARTH_RATE * tau), np.sin(EARTH_RATE * tau), 1.0]) for tau in (0.0, tk)]
            g_i = [expm_so3(axis * EARTH_RATE * tau) @ g_n for tau in (0.0, tk)]
            c_ib0_i = triad(*gravity, *g_i)
            c_est = expm_so3(axis * EARTH_RATE * tk).T @ c_ib0_i @ c
            err = c_est @ c_bn[k].T
            level = np.hypot(err[2, 1], err[0, 2])
    return x[9:], sigma, level


def reference(seed: int, lean: bool) -> None:
    bias, sigma, level = estimate(*truth(seed), lean=lean)
    print(f"reference{' (lean)' if lean else ''}: bias error {np.round((bias - ACCEL_BIAS) / UG, 2)} ug, sigma {np.round(sigma / UG, 2)} ug, "
          f"level alignment error {level / DEG:.5f} deg")


def best_wall(cmd: list[str], repeat: int) -> float:
    """The best wall time of ``cmd`` over ``repeat`` runs, after one run not timed. Python writes its modules'
    bytecode as on any install (a PYTHONDONTWRITEBYTECODE of this shell left out), so every timed run reads it."""
    env = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}
    best = float("inf")
    for k in range(repeat + 1):
        start = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, cwd=ROOT, env=env)
        if k:
            best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--reference", choices=("plain", "lean"), help="run only that reference")
    args = parser.parse_args()
    if args.reference:
        reference(seed=1, lean=args.reference == "lean")
        return
    for kind in ("plain", "lean"):
        subprocess.run([sys.executable, __file__, "--reference", kind], check=True)
    hil = Path(sys.executable).with_name("hil")
    with __import__("tempfile").TemporaryDirectory() as tmp:
        simulate = best_wall([str(hil), "simulate", str(CONFIG), "--out", tmp, "--overwrite"], args.repeat)
    plain, lean = (best_wall([sys.executable, __file__, "--reference", kind], args.repeat) for kind in ("plain", "lean"))
    print(f"hil simulate configs/liu2019_sim.yaml  {simulate:7.3f} s   whole process, best of {args.repeat}")
    print(f"plain numpy reference                  {plain:7.3f} s   ratio {simulate / plain:.3f} (target <= 0.25)")
    print(f"lean numpy reference                   {lean:7.3f} s   ratio {simulate / lean:.3f}")


if __name__ == "__main__":
    main()
