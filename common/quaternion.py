"""Unit quaternions as plain float tuples: the one quaternion module of the project, shared
by the flight core (`fcu.control.dualquat` builds dual quaternions on it), the frame conversion
(`common.frames`) and the ground station. The plant (`sitl.plant`) keeps its own rotation
on purpose: an independent plant is what makes closed-loop tests mean something.

Conventions: Hamilton product, scalar first (w, x, y, z); q rotates body vectors into the
world frame. Scalar code on float tuples, compiled by numba (`common.jit.njit`): the flight
core's kernels (tracker, allocation) call these at machine speed, and Python callers get
tuples back. Written with indexing only, so tuples, lists and arrays of floats all work.
`angle_between_rows` is the vectorised attitude error for logs. Z-Y-X (yaw-pitch-roll)
Euler angles, which the flight code never uses, are here for displays and reports
(`zyx_euler`, `zyx_yaw`, `zyx_euler_rows`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from common.jit import njit

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

Q_IDENTITY: Quat = (1.0, 0.0, 0.0, 0.0)

_SMALL_ANGLE = 1e-6


# ----------------------------------------------------------------------------------------
# Vectors
# ----------------------------------------------------------------------------------------


@njit
def cross(a: Vec3, b: Vec3) -> Vec3:
    ax, ay, az = a[0], a[1], a[2]
    bx, by, bz = b[0], b[1], b[2]
    return (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)


@njit
def norm3(a: Vec3) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


# ----------------------------------------------------------------------------------------
# Quaternions
# ----------------------------------------------------------------------------------------


@njit
def q_mul(a: Quat, b: Quat) -> Quat:
    """Hamilton product a b."""
    aw, ax, ay, az = a[0], a[1], a[2], a[3]
    bw, bx, by, bz = b[0], b[1], b[2], b[3]
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


@njit
def q_conj(q: Quat) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


@njit
def q_norm(q: Quat) -> float:
    return math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])


@njit
def q_normalize(q: Quat) -> Quat:
    n = q_norm(q)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@njit
def q_rotate(q: Quat, v: Vec3) -> Vec3:
    """R(q) v for a unit quaternion (body to world when q = q_wb)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    vx, vy, vz = v[0], v[1], v[2]
    # t = 2 (q_vec x v); v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + y * tz - z * ty,
            vy + w * ty + z * tx - x * tz,
            vz + w * tz + x * ty - y * tx)


@njit
def q_rotate_inv(q: Quat, v: Vec3) -> Vec3:
    """R(q)^T v (world to body when q = q_wb)."""
    return q_rotate((q[0], -q[1], -q[2], -q[3]), v)


@njit
def q_exp(rotvec: Vec3) -> Quat:
    """Unit quaternion of the rotation vector `rotvec` (angle |rotvec| about its axis)."""
    rx, ry, rz = rotvec[0], rotvec[1], rotvec[2]
    half = 0.5 * math.sqrt(rx * rx + ry * ry + rz * rz)
    if half < _SMALL_ANGLE:
        k = 0.5 * (1.0 - half * half / 6.0)  # sin(half)/(2 half) by its series
    else:
        k = 0.5 * math.sin(half) / half
    return (math.cos(half), k * rx, k * ry, k * rz)


def q_exp_many(rx: Any, ry: Any, rz: Any) -> Any:
    """`q_exp` of many rotation vectors at once (components as arrays).

    The same function as q_exp, written with np.sinc where q_exp has its small-angle series
    and sin(half) / half: about 5% of the components differ in the last bits, and the
    envelope check's figures (`fcu.envelope.feasibility`) are those of this form."""
    half = 0.5 * np.sqrt(rx * rx + ry * ry + rz * rz)
    k = 0.5 * np.sinc(half / math.pi)  # sin(half) / (2 half), 1/2 at 0
    return (np.cos(half), k * rx, k * ry, k * rz)


@njit
def q_log(q: Quat) -> Vec3:
    """Rotation vector theta n of a unit quaternion, theta in [0, pi] (shortest path).

    q and -q give the same result except at theta = pi exactly, where n and -n are equal
    rotations.
    """
    w, x, y, z = q[0], q[1], q[2], q[3]
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < _SMALL_ANGLE * 1e-3:
        k = 2.0 / w  # 2 atan2(s, w) / s, limit as s -> 0 (w ~ 1)
    else:
        k = 2.0 * math.atan2(s, w) / s
    return (k * x, k * y, k * z)


@njit
def q_angle(q: Quat) -> float:
    """Rotation angle of q in [0, pi], robust near 0 and pi."""
    s = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return 2.0 * math.atan2(s, abs(q[0]))


def angle_between_rows(q: np.ndarray, q_d: np.ndarray) -> np.ndarray:
    """Angle of q_d* q for rows of (w, x, y, z) quaternions, in [0, pi]."""
    dot = np.abs(np.sum(q * q_d, axis=1))  # |scalar part of q_d* q|
    w1, v1 = q_d[:, 0], -q_d[:, 1:]
    w2, v2 = q[:, 0], q[:, 1:]
    vec = w1[:, None] * v2 + w2[:, None] * v1 + np.cross(v1, v2)
    return np.asarray(2.0 * np.arctan2(np.linalg.norm(vec, axis=1), dot))


def rotate_rows(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows of q (w, x, y, z) applied to rows of v: q v q* (body to world for q_enu_flu)."""
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * np.cross(u, v)
    return np.asarray(v + w * t + np.cross(u, t))


# ----------------------------------------------------------------------------------------
# Z-Y-X Euler angles (displays, reports, headings on the wire)
# ----------------------------------------------------------------------------------------


def zyx_yaw(q: Quat) -> float:
    """The Z-Y-X yaw of q in (-pi, pi], rad (a heading: q_ned_frd gives the NED yaw)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def zyx_euler(q: Quat) -> Vec3:
    """(roll, pitch, yaw) of q in rad, Z-Y-X order: q = Rz(yaw) Ry(pitch) Rx(roll); the
    pitch's sine is clipped to [-1, 1] (rounding at gimbal lock)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - x * z))))
    return roll, pitch, zyx_yaw(q)


def zyx_euler_rows(q: np.ndarray) -> np.ndarray:
    """`zyx_euler` of rows (w, x, y, z): rows (roll, pitch, yaw) in rad."""
    w, x, y, z = q.T
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - x * z), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.column_stack([roll, pitch, yaw])
