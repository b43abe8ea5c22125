"""The nominal wrench along a reference, the one that makes the vehicle follow it exactly
(docs/model.md#dynamics with zero tracking error; `fcu.envelope.feasibility` allocates it):

    f_b = m R(q)^T (a - g_W),  g_W = [0, 0, -g];   tau_b = J omega_dot + omega x J omega,

for one sample (`nominal_wrench_kernel`, compiled: the flight core's too) or many at once
(arrays: `nominal_wrench`, the kernels' rows).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common.config.scenario import VehicleConfig
from common.jit import njit
from fcu.control.dualquat import Quat, Vec3, cross, q_rotate_inv
from fcu.stages import Reference


@njit
def nominal_wrench_kernel(m: float, g: float, inertia: Vec3, q: Quat, a: Vec3, w: Vec3,
                          wd: Vec3) -> tuple[Vec3, Vec3]:
    """(f_b, tau_b) that follow a reference exactly: m R^T (a - g_W), J omega' + omega x J
    omega, for its attitude q, acceleration a, rate w and rate derivative wd."""
    force = q_rotate_inv(q, (m * a[0], m * a[1], m * (a[2] + g)))
    jx, jy, jz = inertia[0], inertia[1], inertia[2]
    gyro = cross(w, (jx * w[0], jy * w[1], jz * w[2]))
    return force, (jx * wd[0] + gyro[0], jy * wd[1] + gyro[1], jz * wd[2] + gyro[2])


@njit
def _nominal_wrench_rows(m: float, g: float, inertia: Vec3, q: np.ndarray, a: np.ndarray,
                         w: np.ndarray, wd: np.ndarray) -> np.ndarray:
    """nominal_wrench_kernel per sample: columns of q (4 x n), a, w, wd (3 x n) -> 6 x n."""
    n = q.shape[1]
    out = np.empty((6, n))
    for i in range(n):
        f, t = nominal_wrench_kernel(m, g, inertia, (q[0, i], q[1, i], q[2, i], q[3, i]),
                                     (a[0, i], a[1, i], a[2, i]), (w[0, i], w[1, i], w[2, i]),
                                     (wd[0, i], wd[1, i], wd[2, i]))
        out[0, i], out[1, i], out[2, i] = f
        out[3, i], out[4, i], out[5, i] = t
    return out


@njit
def wrench_matrix(m: float, g: float, inertia: Vec3, q: np.ndarray, a: np.ndarray,
                  w: np.ndarray, wd: np.ndarray, out: np.ndarray) -> None:
    """`_nominal_wrench_rows` into out (n x 6: a sample's force and torque per row, the
    matrix `Envelope` allocates)."""
    for i in range(q.shape[1]):
        f, t = nominal_wrench_kernel(m, g, inertia, (q[0, i], q[1, i], q[2, i], q[3, i]),
                                     (a[0, i], a[1, i], a[2, i]), (w[0, i], w[1, i], w[2, i]),
                                     (wd[0, i], wd[1, i], wd[2, i]))
        out[i, 0], out[i, 1], out[i, 2] = f
        out[i, 3], out[i, 4], out[i, 5] = t


def nominal_wrench(vehicle: VehicleConfig, ref: Reference) -> tuple[Vec3, Vec3]:
    """(f_b, tau_b) that follow `ref` exactly: m R^T (a - g_W), J omega' + omega x J omega.

    Fields may be floats or numpy arrays (many samples at once: the result's parts are then
    arrays)."""
    m, g, inertia = vehicle.mass_kg, vehicle.gravity_m_s2, vehicle.inertia_diag_kg_m2
    parts = (ref.q_enu_flu, ref.a_enu_m_s2, ref.omega_flu_rad_s, ref.omega_dot_flu_rad_s2)
    if all(isinstance(c, float) for p in parts for c in p):
        return nominal_wrench_kernel(m, g, inertia, *parts)
    n = max(np.size(c) for p in parts for c in p)
    q, a, w, wd = (np.array([np.broadcast_to(np.asarray(c, dtype=np.float64), (n,))
                             for c in p]) for p in parts)
    out = _nominal_wrench_rows(m, g, inertia, q, a, w, wd)
    return (out[0], out[1], out[2]), (out[3], out[4], out[5])


def rows(parts: Any, n: int) -> np.ndarray:
    """Components (floats or arrays of n) as the rows of a float array (len(parts) x n)."""
    out = np.empty((len(parts), n))
    for j, c in enumerate(parts):
        out[j] = c
    return out
