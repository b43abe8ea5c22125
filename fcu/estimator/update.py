"""The measurement update: Joseph form, injection and reset (Sola sec. 6.2-6.3).

The pose measures position and attitude directly, so H is a selector (rows of I15); the
attitude innovation is log(q_hat* q_meas), a local (body) rotation vector.
"""

from __future__ import annotations

import math

import numpy as np

from common.quaternion import q_exp, q_mul
from fcu.estimator.strapdown import N, State

I15 = np.eye(N)
H_POS = I15[[0, 1, 2]]  # measurement selectors
H_ATT = I15[[6, 7, 8]]
H_BOTH = I15[[0, 1, 2, 6, 7, 8]]
_G_IDX = np.array([6 * N + 7, 6 * N + 8, 7 * N + 6, 7 * N + 8, 8 * N + 6, 8 * N + 7])


def joseph_update(P: np.ndarray, H: np.ndarray, y: list[float], r: list[float]
                  ) -> tuple[np.ndarray, list[float]]:
    """(P after the update, the error-state correction dx): Joseph form with the selector H,
    symmetrised, the attitude reset G = I - [dtheta/2]x (Sola eq. 287) folded in:
    P = (G A) P (G A)^T + (G K) R (G K)^T, A = I - K H."""
    pht = P.dot(H.T)
    S = H.dot(pht)
    S.flat[::len(r) + 1] += r
    K = pht.dot(np.linalg.inv(S))
    dx = K.dot(y).tolist()
    hx, hy, hz = 0.5 * dx[6], 0.5 * dx[7], 0.5 * dx[8]
    Gr = I15.copy()
    Gr.flat[_G_IDX] = (hz, -hy, -hz, hx, hy, -hx)
    A = Gr.dot(I15 - K.dot(H))
    GK = Gr.dot(K)
    P = A.dot(P).dot(A.T)
    P += (GK * r).dot(GK.T)
    P += P.T
    P *= 0.5
    return P, dx


def inject(x: State, dx: list[float]) -> State:
    """The nominal state corrected by dx (Sola eq. 282-283): q = q exp(dtheta), renormalised."""
    q = q_mul((x[6], x[7], x[8], x[9]), q_exp((dx[6], dx[7], dx[8])))
    n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (x[0] + dx[0], x[1] + dx[1], x[2] + dx[2],
            x[3] + dx[3], x[4] + dx[4], x[5] + dx[5],
            q[0] * n, q[1] * n, q[2] * n, q[3] * n,
            x[10] + dx[9], x[11] + dx[10], x[12] + dx[11],
            x[13] + dx[12], x[14] + dx[13], x[15] + dx[14])


def bound_covariance(P: np.ndarray, var_min: np.ndarray, var_max: float) -> None:
    """Diagonal floors and the var_max clamp, in place (row/column scaling keeps P SPD)."""
    d = P.diagonal()
    if (d < var_min).any():
        P.flat[::16] = np.maximum(d, var_min)
    if (d > var_max).any():
        k = np.sqrt(np.minimum(1.0, var_max / np.maximum(d, 1e-300)))
        P *= k[:, None]
        P *= k[None, :]


def reset_block(x: State, P: np.ndarray, i0: int, z: tuple[float, ...], r: float) -> State:
    """EKF2-style reset to the pose: the position (i0 = 0) or attitude (i0 = 6) set to z,
    its covariance rows and columns cleared to r I, in place; returns the new state."""
    xs = list(x)
    if i0 == 0:
        xs[0:3] = z[0:3]
    else:
        xs[6:10] = z[0:4]
    P[i0:i0 + 3, :] = 0.0
    P[:, i0:i0 + 3] = 0.0
    P[i0:i0 + 3, i0:i0 + 3] = np.eye(3) * r
    return (xs[0], xs[1], xs[2], xs[3], xs[4], xs[5], xs[6], xs[7], xs[8], xs[9], xs[10],
            xs[11], xs[12], xs[13], xs[14], xs[15])
