"""The output predictor: the state at the newest IMU sample from the delayed horizon.

The output state integrates each new sample once; a horizon correction is carried to it by
the linearised transition over the buffered interval (no lag, no EKF2-style feedback time
constant), or the buffered samples are re-propagated exactly. Compiled (`common.jit.njit`).
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit
from common.quaternion import Quat, q_conj, q_exp, q_mul, q_rotate
from fcu.estimator.strapdown import State, strapdown


@njit
def propagate(x: State, t_us: int, pend_t: np.ndarray, pend_v: np.ndarray, head: int,
              n: int, g: float) -> tuple[State, int]:
    """(state, time) of x at t_us propagated over the n buffered samples from `head` of the
    ring (pend_t their times, pend_v their gyro and accel), Sola eq. 260 each."""
    cap = pend_t.shape[0]
    for k in range(n):
        j = (head + k) % cap
        v = pend_v[j]
        x = strapdown(x, (v[0], v[1], v[2]), (v[3], v[4], v[5]), (pend_t[j] - t_us) * 1e-6, g)
        t_us = pend_t[j]
    return x, t_us


@njit
def corrected_output(xb: State, xa: State, xo: State, T: float, g: float) -> State:
    """The output state xo, T after the horizon, given the horizon's correction xb -> xa.

    Linearised over the buffered interval T: dp += T dv - T/2 dV x dth_W - T^2/2 R db_a,
    dv += -dV x dth_W - T R db_a + T/2 dV x R db_g, q_o = q_h (q_hb* q_o) exp(-T db_g),
    dV the interval's world specific-force integral.
    """
    qb: Quat = (xb[6], xb[7], xb[8], xb[9])
    qa: Quat = (xa[6], xa[7], xa[8], xa[9])
    e = q_mul(qa, q_conj(qb))  # world-frame correction rotation
    sg = 2.0 if e[0] >= 0.0 else -2.0
    thx, thy, thz = sg * e[1], sg * e[2], sg * e[3]
    dvx = xo[3] - xb[3]
    dvy = xo[4] - xb[4]
    dvz = xo[5] - xb[5] + g * T
    ba = q_rotate(qb, (xa[13] - xb[13], xa[14] - xb[14], xa[15] - xb[15]))
    dbg = (xa[10] - xb[10], xa[11] - xb[11], xa[12] - xb[12])
    bg = q_rotate(qb, dbg)
    # c = dV x dth_W, d = dV x R db_g
    cx = dvy * thz - dvz * thy
    cy = dvz * thx - dvx * thz
    cz = dvx * thy - dvy * thx
    ex = dvy * bg[2] - dvz * bg[1]
    ey = dvz * bg[0] - dvx * bg[2]
    ez = dvx * bg[1] - dvy * bg[0]
    h = 0.5 * T
    ux = xa[3] - xb[3]
    uy = xa[4] - xb[4]
    uz = xa[5] - xb[5]
    q = q_mul(q_mul(qa, q_mul(q_conj(qb), (xo[6], xo[7], xo[8], xo[9]))),
              q_exp((-T * dbg[0], -T * dbg[1], -T * dbg[2])))
    k = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (xo[0] + xa[0] - xb[0] + T * ux - h * cx - h * T * ba[0],
            xo[1] + xa[1] - xb[1] + T * uy - h * cy - h * T * ba[1],
            xo[2] + xa[2] - xb[2] + T * uz - h * cz - h * T * ba[2],
            xo[3] + ux - cx - T * ba[0] + h * ex,
            xo[4] + uy - cy - T * ba[1] + h * ey,
            xo[5] + uz - cz - T * ba[2] + h * ez,
            q[0] * k, q[1] * k, q[2] * k, q[3] * k,
            xa[10], xa[11], xa[12], xa[13], xa[14], xa[15])
