"""Unit quaternions and unit dual quaternions as plain float tuples (paper Section II-A).

Conventions: Hamilton product, scalar first (w, x, y, z). A pose is the unit dual quaternion
q_hat = q + eps d with d = 1/2 q p_b = 1/2 p_s q (eq. 1), q rotating body vectors into the
world frame, p_s the position in the world frame and p_b = R(q)^T p_s. A dual vector
(a pure dual quaternion) is a 6-tuple (real xyz, dual xyz), e.g. a twist omega + eps v.

Everything is scalar code on tuples: these functions run in the 500 Hz control step, where
many small numpy calls would cost more than the arithmetic.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
DualQuat = tuple[float, float, float, float, float, float, float, float]
DualVec = tuple[float, float, float, float, float, float]

Q_IDENTITY: Quat = (1.0, 0.0, 0.0, 0.0)
DQ_IDENTITY: DualQuat = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

_SMALL_ANGLE = 1e-6


# ----------------------------------------------------------------------------------------
# Vectors
# ----------------------------------------------------------------------------------------


def cross(a: Vec3, b: Vec3) -> Vec3:
    ax, ay, az = a
    bx, by, bz = b
    return (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)


def norm3(a: Vec3) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


# ----------------------------------------------------------------------------------------
# Quaternions
# ----------------------------------------------------------------------------------------


def q_mul(a: Quat, b: Quat) -> Quat:
    """Hamilton product a b."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def q_conj(q: Quat) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def q_norm(q: Quat) -> float:
    return math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])


def q_normalize(q: Quat) -> Quat:
    n = q_norm(q)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def q_rotate(q: Quat, v: Vec3) -> Vec3:
    """R(q) v for a unit quaternion (body to world when q = q_wb)."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 (q_vec x v); v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + y * tz - z * ty,
            vy + w * ty + z * tx - x * tz,
            vz + w * tz + x * ty - y * tx)


def q_rotate_inv(q: Quat, v: Vec3) -> Vec3:
    """R(q)^T v (world to body when q = q_wb)."""
    return q_rotate((q[0], -q[1], -q[2], -q[3]), v)


def q_exp(rotvec: Vec3) -> Quat:
    """Unit quaternion of the rotation vector `rotvec` (angle |rotvec| about its axis)."""
    rx, ry, rz = rotvec
    half = 0.5 * math.sqrt(rx * rx + ry * ry + rz * rz)
    if half < _SMALL_ANGLE:
        k = 0.5 * (1.0 - half * half / 6.0)  # sin(half)/(2 half) by its series
    else:
        k = 0.5 * math.sin(half) / half
    return (math.cos(half), k * rx, k * ry, k * rz)


def q_log(q: Quat) -> Vec3:
    """Rotation vector theta n of a unit quaternion, theta in [0, pi] (shortest path).

    q and -q give the same result except at theta = pi exactly, where n and -n are equal
    rotations.
    """
    w, x, y, z = q
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < _SMALL_ANGLE * 1e-3:
        k = 2.0 / w  # 2 atan2(s, w) / s, limit as s -> 0 (w ~ 1)
    else:
        k = 2.0 * math.atan2(s, w) / s
    return (k * x, k * y, k * z)


def q_angle(q: Quat) -> float:
    """Rotation angle of q in [0, pi], robust near 0 and pi."""
    s = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return 2.0 * math.atan2(s, abs(q[0]))


# ----------------------------------------------------------------------------------------
# Dual quaternions
# ----------------------------------------------------------------------------------------


def dq_mul(a: DualQuat, b: DualQuat) -> DualQuat:
    """(ar + eps ad)(br + eps bd) = ar br + eps (ar bd + ad br)."""
    ar, ad = a[:4], a[4:]
    br, bd = b[:4], b[4:]
    r = q_mul(ar, br)
    d1 = q_mul(ar, bd)
    d2 = q_mul(ad, br)
    return (*r, d1[0] + d2[0], d1[1] + d2[1], d1[2] + d2[2], d1[3] + d2[3])


def dq_conj(a: DualQuat) -> DualQuat:
    """Quaternion conjugate of both parts (the inverse of a unit dual quaternion)."""
    return (a[0], -a[1], -a[2], -a[3], a[4], -a[5], -a[6], -a[7])


def dq_norm(a: DualQuat) -> tuple[float, float]:
    """Dual-number norm (r, d) with ||a||^2 = a a*; a unit dual quaternion gives (1, 0)."""
    r = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3])
    dot = a[0] * a[4] + a[1] * a[5] + a[2] * a[6] + a[3] * a[7]
    return (r, dot / r)


def dq_from_pose(q: Quat, p_s: Vec3) -> DualQuat:
    """q_hat = q + eps 1/2 p_s q (eq. 1)."""
    w, x, y, z = q
    px, py, pz = p_s
    # 1/2 (0, p) q
    return (w, x, y, z,
            0.5 * (-px * x - py * y - pz * z),
            0.5 * (px * w + py * z - pz * y),
            0.5 * (-px * z + py * w + pz * x),
            0.5 * (px * y - py * x + pz * w))


def dq_position_world(a: DualQuat) -> Vec3:
    """p_s = 2 d q*."""
    d = q_mul(a[4:], q_conj(a[:4]))
    return (2.0 * d[1], 2.0 * d[2], 2.0 * d[3])


def dq_position_body(a: DualQuat) -> Vec3:
    """p_b = 2 q* d."""
    d = q_mul(q_conj(a[:4]), a[4:])
    return (2.0 * d[1], 2.0 * d[2], 2.0 * d[3])


def dq_to_pose(a: DualQuat) -> tuple[Quat, Vec3]:
    """(q, p_s) of a unit dual quaternion."""
    return a[:4], dq_position_world(a)


def dq_log(a: DualQuat) -> DualVec:
    """ln q_hat = 1/2 (theta n + eps p_b), theta in [0, pi] (decoupled log, MODEL.md 3).

    Shortest path: a negative scalar part selects -q_hat, which is the same pose.
    """
    r = q_log(a[:4])
    pb = dq_position_body(a)  # invariant under q_hat -> -q_hat
    return (0.5 * r[0], 0.5 * r[1], 0.5 * r[2], 0.5 * pb[0], 0.5 * pb[1], 0.5 * pb[2])


def dq_exp(v: DualVec) -> DualQuat:
    """Inverse of `dq_log`: q = exp of the rotation vector 2 v_r, p_b = 2 v_d."""
    q = q_exp((2.0 * v[0], 2.0 * v[1], 2.0 * v[2]))
    # d = 1/2 q p_b = q (0, v_d)
    d = q_mul(q, (0.0, v[3], v[4], v[5]))
    return (*q, *d)


def dq_ad(a: DualQuat, v: DualVec) -> DualVec:
    """Ad_{q_hat} v_hat = q_hat v_hat q_hat* (eq. 2) for unit q_hat.

    With q_hat = q + eps 1/2 p_s q: Ad (w + eps u) = R w + eps (R u + p_s x R w).
    """
    q = a[:4]
    rw = q_rotate(q, v[:3])
    ru = q_rotate(q, v[3:])
    ps = dq_position_world(a)
    c = cross(ps, rw)
    return (rw[0], rw[1], rw[2], ru[0] + c[0], ru[1] + c[1], ru[2] + c[2])


def dual_cross(a: DualVec, b: DualVec) -> DualVec:
    """a x b = a_r x b_r + eps (a_r x b_d + a_d x b_r)."""
    r = cross(a[:3], b[:3])
    d1 = cross(a[:3], b[3:])
    d2 = cross(a[3:], b[:3])
    return (r[0], r[1], r[2], d1[0] + d2[0], d1[1] + d2[1], d1[2] + d2[2])


def gain_dot(k_r: Vec3, k_d: Vec3, v: DualVec) -> DualVec:
    """k_hat . v_hat = K_r v_r + eps K_d v_d with diagonal K_r, K_d (eq. 3)."""
    return (k_r[0] * v[0], k_r[1] * v[1], k_r[2] * v[2],
            k_d[0] * v[3], k_d[1] * v[4], k_d[2] * v[5])


def dv_add(a: DualVec, b: DualVec) -> DualVec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3], a[4] + b[4], a[5] + b[5])


def dv_sub(a: DualVec, b: DualVec) -> DualVec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3], a[4] - b[4], a[5] - b[5])


def dv_scale(k: float, a: DualVec) -> DualVec:
    return (k * a[0], k * a[1], k * a[2], k * a[3], k * a[4], k * a[5])
