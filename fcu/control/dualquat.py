"""Unit dual quaternions as plain float tuples (paper Section II-A), on the quaternions of
`common.quaternion` (re-exported here for the flight core).

Conventions: Hamilton product, scalar first (w, x, y, z). A pose is the unit dual quaternion
q_hat = q + eps d with d = 1/2 q p_b = 1/2 p_s q (eq. 1), q rotating body vectors into the
world frame, p_s the position in the world frame and p_b = R(q)^T p_s. A dual vector
(a pure dual quaternion) is a 6-tuple (real xyz, dual xyz), e.g. a twist omega + eps v.

Everything is scalar code on float tuples, compiled by numba (`common.jit.njit`): the
tracker's kernel calls these at machine speed; Python callers get tuples back.
"""

from __future__ import annotations

import math

from common.jit import njit
from common.quaternion import Q_IDENTITY as Q_IDENTITY
from common.quaternion import Quat as Quat
from common.quaternion import Vec3 as Vec3
from common.quaternion import cross as cross
from common.quaternion import norm3 as norm3
from common.quaternion import q_angle as q_angle
from common.quaternion import q_conj as q_conj
from common.quaternion import q_exp as q_exp
from common.quaternion import q_log as q_log
from common.quaternion import q_mul as q_mul
from common.quaternion import q_norm as q_norm
from common.quaternion import q_normalize as q_normalize
from common.quaternion import q_rotate as q_rotate
from common.quaternion import q_rotate_inv as q_rotate_inv

DualQuat = tuple[float, float, float, float, float, float, float, float]
DualVec = tuple[float, float, float, float, float, float]

DQ_IDENTITY: DualQuat = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


# ----------------------------------------------------------------------------------------
# Dual quaternions
# ----------------------------------------------------------------------------------------


@njit
def dq_mul(a: DualQuat, b: DualQuat) -> DualQuat:
    """(ar + eps ad)(br + eps bd) = ar br + eps (ar bd + ad br)."""
    ar, ad = (a[0], a[1], a[2], a[3]), (a[4], a[5], a[6], a[7])
    br, bd = (b[0], b[1], b[2], b[3]), (b[4], b[5], b[6], b[7])
    r = q_mul(ar, br)
    d1 = q_mul(ar, bd)
    d2 = q_mul(ad, br)
    return (r[0], r[1], r[2], r[3], d1[0] + d2[0], d1[1] + d2[1], d1[2] + d2[2], d1[3] + d2[3])


@njit
def dq_conj(a: DualQuat) -> DualQuat:
    """Quaternion conjugate of both parts (the inverse of a unit dual quaternion)."""
    return (a[0], -a[1], -a[2], -a[3], a[4], -a[5], -a[6], -a[7])


@njit
def dq_norm(a: DualQuat) -> tuple[float, float]:
    """Dual-number norm (r, d) with ||a||^2 = a a*; a unit dual quaternion gives (1, 0)."""
    r = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3])
    dot = a[0] * a[4] + a[1] * a[5] + a[2] * a[6] + a[3] * a[7]
    return (r, dot / r)


@njit
def dq_from_pose(q: Quat, p_s: Vec3) -> DualQuat:
    """q_hat = q + eps 1/2 p_s q (eq. 1)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    px, py, pz = p_s[0], p_s[1], p_s[2]
    # 1/2 (0, p) q
    return (w, x, y, z,
            0.5 * (-px * x - py * y - pz * z),
            0.5 * (px * w + py * z - pz * y),
            0.5 * (-px * z + py * w + pz * x),
            0.5 * (px * y - py * x + pz * w))


@njit
def dq_position_world(a: DualQuat) -> Vec3:
    """p_s = 2 d q*."""
    d = q_mul((a[4], a[5], a[6], a[7]), (a[0], -a[1], -a[2], -a[3]))
    return (2.0 * d[1], 2.0 * d[2], 2.0 * d[3])


@njit
def dq_position_body(a: DualQuat) -> Vec3:
    """p_b = 2 q* d."""
    d = q_mul((a[0], -a[1], -a[2], -a[3]), (a[4], a[5], a[6], a[7]))
    return (2.0 * d[1], 2.0 * d[2], 2.0 * d[3])


@njit
def dq_to_pose(a: DualQuat) -> tuple[Quat, Vec3]:
    """(q, p_s) of a unit dual quaternion."""
    return (a[0], a[1], a[2], a[3]), dq_position_world(a)


@njit
def dq_log(a: DualQuat) -> DualVec:
    """ln q_hat = 1/2 (theta n + eps p_b), theta in [0, pi] (decoupled log,
    docs/design.md#corrections).

    Shortest path: a negative scalar part selects -q_hat, which is the same pose.
    """
    r = q_log((a[0], a[1], a[2], a[3]))
    pb = dq_position_body(a)  # invariant under q_hat -> -q_hat
    return (0.5 * r[0], 0.5 * r[1], 0.5 * r[2], 0.5 * pb[0], 0.5 * pb[1], 0.5 * pb[2])


@njit
def dq_exp(v: DualVec) -> DualQuat:
    """Inverse of `dq_log`: q = exp of the rotation vector 2 v_r, p_b = 2 v_d."""
    q = q_exp((2.0 * v[0], 2.0 * v[1], 2.0 * v[2]))
    # d = 1/2 q p_b = q (0, v_d)
    d = q_mul(q, (0.0, v[3], v[4], v[5]))
    return (q[0], q[1], q[2], q[3], d[0], d[1], d[2], d[3])


@njit
def dq_ad(a: DualQuat, v: DualVec) -> DualVec:
    """Ad_{q_hat} v_hat = q_hat v_hat q_hat* (eq. 2) for unit q_hat.

    With q_hat = q + eps 1/2 p_s q: Ad (w + eps u) = R w + eps (R u + p_s x R w).
    """
    q = (a[0], a[1], a[2], a[3])
    rw = q_rotate(q, (v[0], v[1], v[2]))
    ru = q_rotate(q, (v[3], v[4], v[5]))
    ps = dq_position_world(a)
    c = cross(ps, rw)
    return (rw[0], rw[1], rw[2], ru[0] + c[0], ru[1] + c[1], ru[2] + c[2])


@njit
def dual_cross(a: DualVec, b: DualVec) -> DualVec:
    """a x b = a_r x b_r + eps (a_r x b_d + a_d x b_r)."""
    ar, ad = (a[0], a[1], a[2]), (a[3], a[4], a[5])
    br, bd = (b[0], b[1], b[2]), (b[3], b[4], b[5])
    r = cross(ar, br)
    d1 = cross(ar, bd)
    d2 = cross(ad, br)
    return (r[0], r[1], r[2], d1[0] + d2[0], d1[1] + d2[1], d1[2] + d2[2])


@njit
def gain_dot(k_r: Vec3, k_d: Vec3, v: DualVec) -> DualVec:
    """k_hat . v_hat = K_r v_r + eps K_d v_d with diagonal K_r, K_d (eq. 3)."""
    return (k_r[0] * v[0], k_r[1] * v[1], k_r[2] * v[2],
            k_d[0] * v[3], k_d[1] * v[4], k_d[2] * v[5])


@njit
def right_jacobian_inv(phi: Vec3, w: Vec3) -> Vec3:
    """J_r(phi)^-1 w, SO(3)'s inverse right Jacobian: how a rotation vector phi changes for
    a body rate w of exp(phi), w + 1/2 phi x w + c phi x (phi x w) with
    c = 1/theta^2 - cot(theta/2) / (2 theta) (its series 1/12 + theta^2/720 below
    theta^2 = 1e-8), theta = |phi| < 2 pi."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    if th2 < 1e-8:
        c = 1.0 / 12.0 + th2 / 720.0
    else:
        th = math.sqrt(th2)
        c = 1.0 / th2 - 0.5 / (th * math.tan(0.5 * th))
    pw = cross(phi, w)
    ppw = cross(phi, pw)
    return (w[0] + 0.5 * pw[0] + c * ppw[0], w[1] + 0.5 * pw[1] + c * ppw[1],
            w[2] + 0.5 * pw[2] + c * ppw[2])
