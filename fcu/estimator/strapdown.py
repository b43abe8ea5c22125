"""The nominal state's strapdown step and the error state's transition over an interval.

State x = (p, v, q, b_g, b_a) as one flat tuple of 16 floats (world ENU, body FLU); error
state dx = [dp, dv, dtheta, db_g, db_a] (15), dtheta the local (body) attitude error.

Compiled (`common.jit.njit`): the filter's kernels (`fcu.estimator.filter`) call these on
tuples loaded from their flat buffers (`load_state`, `store_state`); Python callers get
tuples back, the same floats as the interpreted arithmetic.
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit
from common.quaternion import Vec3

N = 15  # error-state dimension
State = tuple[float, float, float, float, float, float, float, float, float, float,
               float, float, float, float, float, float]


@njit
def load_state(a: np.ndarray, i: int) -> State:
    """The 16 floats of a state at offset i of a flat array, as a tuple."""
    return (a[i], a[i + 1], a[i + 2], a[i + 3], a[i + 4], a[i + 5], a[i + 6], a[i + 7],
            a[i + 8], a[i + 9], a[i + 10], a[i + 11], a[i + 12], a[i + 13], a[i + 14],
            a[i + 15])


@njit
def store_state(a: np.ndarray, i: int, x: State) -> None:
    """A state into a flat array at offset i."""
    for k in range(16):
        a[i + k] = x[k]


@njit
def strapdown(x: State, w: Vec3, f: Vec3, dt: float, g: float) -> State:
    """One IMU sample over dt (Sola eq. 260), specific force rotated to mid-interval."""
    (px, py, pz, vx, vy, vz, qw, qx, qy, qz, bgx, bgy, bgz, bax, bay, baz) = x
    rx = (w[0] - bgx) * dt
    ry = (w[1] - bgy) * dt
    rz = (w[2] - bgz) * dt
    ax = f[0] - bax
    ay = f[1] - bay
    az = f[2] - baz
    mx = ax + 0.5 * (ry * az - rz * ay)
    my = ay + 0.5 * (rz * ax - rx * az)
    mz = az + 0.5 * (rx * ay - ry * ax)
    tx = 2.0 * (qy * mz - qz * my)
    ty = 2.0 * (qz * mx - qx * mz)
    tz = 2.0 * (qx * my - qy * mx)
    awx = mx + qw * tx + qy * tz - qz * ty
    awy = my + qw * ty + qz * tx - qx * tz
    awz = mz + qw * tz + qx * ty - qy * tx - g
    hdt = 0.5 * dt
    px += (vx + hdt * awx) * dt
    py += (vy + hdt * awy) * dt
    pz += (vz + hdt * awz) * dt
    vx += awx * dt
    vy += awy * dt
    vz += awz * dt
    h2 = 0.25 * (rx * rx + ry * ry + rz * rz)
    if h2 < 1e-4:
        c = 1.0 - h2 * (0.5 - h2 / 24.0)
        s = 0.5 * (1.0 - h2 * (1.0 / 6.0 - h2 / 120.0))
    else:
        h = math.sqrt(h2)
        c = math.cos(h)
        s = 0.5 * math.sin(h) / h
    dx = s * rx
    dy = s * ry
    dz = s * rz
    nw = qw * c - qx * dx - qy * dy - qz * dz
    nx = qw * dx + qx * c + qy * dz - qz * dy
    ny = qw * dy - qx * dz + qy * c + qz * dx
    nz = qw * dz + qx * dy - qy * dx + qz * c
    k = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    return (px, py, pz, vx, vy, vz, nw * k, nx * k, ny * k, nz * k,
             bgx, bgy, bgz, bax, bay, baz)


def _flat_indices() -> np.ndarray:
    """Flat indices into F of its 60 time-varying entries, in `transition_entries`' order."""
    rc = [(i, 3 + i) for i in range(3)]
    for r0, c0 in ((0, 6), (0, 12), (3, 6), (3, 9), (3, 12), (6, 6)):
        rc += [(r0 + i, c0 + j) for i in range(3) for j in range(3)]
    rc += [(6 + i, 9 + i) for i in range(3)]
    return np.array([r * N + c for r, c in rc])


F_IDX = _flat_indices()


def _row_columns() -> np.ndarray:
    """For each row of F, the columns that can be non-zero (the diagonal and F_IDX's), in
    increasing order, padded with -1: 72 of F's 225 entries."""
    cols = [{i} for i in range(N)]
    for f in F_IDX:
        cols[f // N].add(int(f % N))
    out = np.full((N, max(len(c) for c in cols)), -1, dtype=np.int64)
    for i, c in enumerate(cols):
        out[i, :len(c)] = sorted(c)
    return out


F_COLS = _row_columns()


@njit
def f_p_ft(F: np.ndarray, P: np.ndarray) -> np.ndarray:
    """F P F^T over F's possibly non-zero entries (`F_COLS`): about 2,200 multiplications
    where the dense products take 6,750; the same sums but for their order and the terms
    of F's zeros."""
    n = P.shape[0]
    w = F_COLS.shape[1]
    FP = np.zeros((n, n))
    for i in range(n):
        for c in range(w):
            k = F_COLS[i, c]
            if k < 0:
                break
            f = F[i, k]
            for j in range(n):
                FP[i, j] += f * P[k, j]
    out = np.empty((n, n))
    for j in range(n):
        for i in range(n):
            t = 0.0
            for c in range(w):
                k = F_COLS[j, c]
                if k < 0:
                    break
                t += FP[i, k] * F[j, k]
            out[i, j] = t
    return out


@njit
def transition_entries(x0: State, x1: State, T: float, g: float) -> tuple[float, ...]:
    """The 60 time-varying entries of F (at F_IDX) over an interval T from x0 to x1.

    F from the interval's deltas as EKF2 does on its down-sampled IMU (Sola eq. 269-270):
    with dV = v1 - v0 - g_W T (world specific-force integral), R [a]x T = [dV]x R, so
    dv/dtheta = -[dV]x R, dv/db_a = -R T, dtheta/dtheta = I - [dtheta_01]x,
    dtheta/db_g = -I T, and the half-interval terms dp/dtheta, dp/db_a, dv/db_g.
    """
    # mid-interval attitude (nlerp) and body rotation over the interval
    aw, ax, ay, az = x0[6], x0[7], x0[8], x0[9]
    bw, bx, by, bz = x1[6], x1[7], x1[8], x1[9]
    qw, qx, qy, qz = aw + bw, ax + bx, ay + by, az + bz
    k = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    qw, qx, qy, qz = qw * k, qx * k, qy * k, qz * k
    # 2 vec(q0* q1): the rotation vector to first order
    ex = 2.0 * (aw * bx - ax * bw - ay * bz + az * by)
    ey = 2.0 * (aw * by + ax * bz - ay * bw - az * bx)
    ez = 2.0 * (aw * bz - ax * by + ay * bx - az * bw)
    dvx = x1[3] - x0[3]
    dvy = x1[4] - x0[4]
    dvz = x1[5] - x0[5] + g * T
    xx, yy, zz = qx * qx, qy * qy, qz * qz
    xy, xz, yz = qx * qy, qx * qz, qy * qz
    wx, wy, wz = qw * qx, qw * qy, qw * qz
    r00 = 1.0 - 2.0 * (yy + zz)
    r01 = 2.0 * (xy - wz)
    r02 = 2.0 * (xz + wy)
    r10 = 2.0 * (xy + wz)
    r11 = 1.0 - 2.0 * (xx + zz)
    r12 = 2.0 * (yz - wx)
    r20 = 2.0 * (xz - wy)
    r21 = 2.0 * (yz + wx)
    r22 = 1.0 - 2.0 * (xx + yy)
    # M = [dV]x R, rows: dV x (column j of R) ... row i of [dV]x R
    m00 = -dvz * r10 + dvy * r20
    m01 = -dvz * r11 + dvy * r21
    m02 = -dvz * r12 + dvy * r22
    m10 = dvz * r00 - dvx * r20
    m11 = dvz * r01 - dvx * r21
    m12 = dvz * r02 - dvx * r22
    m20 = -dvy * r00 + dvx * r10
    m21 = -dvy * r01 + dvx * r11
    m22 = -dvy * r02 + dvx * r12
    h = 0.5 * T
    hh = h * T
    return (T, T, T,
            -h * m00, -h * m01, -h * m02, -h * m10, -h * m11, -h * m12,
            -h * m20, -h * m21, -h * m22,
            -hh * r00, -hh * r01, -hh * r02, -hh * r10, -hh * r11, -hh * r12,
            -hh * r20, -hh * r21, -hh * r22,
            -m00, -m01, -m02, -m10, -m11, -m12, -m20, -m21, -m22,
            h * m00, h * m01, h * m02, h * m10, h * m11, h * m12, h * m20, h * m21, h * m22,
            -T * r00, -T * r01, -T * r02, -T * r10, -T * r11, -T * r12,
            -T * r20, -T * r21, -T * r22,
            1.0, ez, -ey, -ez, 1.0, ex, ey, -ex, 1.0,
            -T, -T, -T)
