"""The measurement update: Joseph form, injection and reset (Sola sec. 6.2-6.3).

The pose measures position and attitude directly, so H is a selector (rows of I15); the
attitude innovation is log(q_hat* q_meas), a local (body) rotation vector.

Compiled (`common.jit.njit`): `joseph_gain`, the innovation covariance's inverse
(`spd_inverse`, by Cholesky: S is symmetric positive definite), then `joseph_apply`. The
inverse is this module's own rather than LAPACK's, so that a fusion is one compiled call and
its result does not depend on the LAPACK a platform's numpy links; it agrees with numpy's
`np.linalg.inv` within 1e-13 relative on the filter's matrices, and the filter's pinned
flight figures (tests/closed_loop/test_reference_figures.py, 1e-9 relative) did not move.
The matrix products are BLAS's dgemm/dgemv through numba's `np.dot`, the same products
numpy's `dot` computes (tests/unit/test_estimator_kernels.py checks them against numpy on
random inputs).
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit
from common.quaternion import q_exp, q_mul
from fcu.estimator.strapdown import N, State


@njit
def joseph_gain(P: np.ndarray, H: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P H^T, S = H P H^T + diag(r)): the first half of the update."""
    pht = np.dot(P, H.T)
    S = np.dot(H, pht)
    for i in range(r.shape[0]):
        S[i, i] += r[i]
    return pht, S


@njit
def cholesky_lower(S: np.ndarray, L: np.ndarray) -> bool:
    """S = L L^T into the zeroed lower-triangular L (S symmetric, its lower triangle read);
    False at the first pivot <= 0 or NaN (S is not positive definite; L then partial)."""
    n = S.shape[0]
    for j in range(n):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        L[j, j] = d
        for i in range(j + 1, n):
            t = S[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
    return True


@njit
def spd_inverse(S: np.ndarray) -> tuple[bool, np.ndarray]:
    """(True, S^-1) for a symmetric positive definite S, by Cholesky (S = L L^T, S^-1 =
    L^-T L^-1, exactly symmetric); (False, NaNs) when S is not (a pivot <= 0 or NaN)."""
    n = S.shape[0]
    L = np.zeros((n, n))
    if not cholesky_lower(S, L):
        return False, np.full((n, n), np.nan)
    Li = np.zeros((n, n))  # L^-1, lower triangular
    for i in range(n):
        Li[i, i] = 1.0 / L[i, i]
        for j in range(i):
            t = 0.0
            for k in range(j, i):
                t -= L[i, k] * Li[k, j]
            Li[i, j] = t / L[i, i]
    inv = np.empty((n, n))
    for i in range(n):
        for j in range(i + 1):
            t = 0.0
            for k in range(i, n):
                t += Li[k, i] * Li[k, j]
            inv[i, j] = t
            inv[j, i] = t
    return True, inv


@njit
def symmetrise(P: np.ndarray) -> None:
    """P = (P + P^T) / 2 in place, as numpy's `P += P.T; P *= 0.5` (buffered) computes it."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i, n):
            s = (P[i, j] + P[j, i]) * 0.5
            P[i, j] = s
            P[j, i] = s


@njit
def joseph_apply(P: np.ndarray, H: np.ndarray, pht: np.ndarray, s_inv: np.ndarray,
                 y: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The second half: K = P H^T S^-1, dx = K y and, in place, P = (G A) P (G A)^T +
    (G K) R (G K)^T, symmetrised, with A = I - K H and the attitude reset
    G = I - [dtheta/2]x (Sola eq. 287) folded in; returns dx."""
    K = np.dot(pht, s_inv)
    dx: np.ndarray = np.dot(K, y)
    hx, hy, hz = 0.5 * dx[6], 0.5 * dx[7], 0.5 * dx[8]
    Gr = np.eye(N)
    Gr[6, 7] = hz
    Gr[6, 8] = -hy
    Gr[7, 6] = -hz
    Gr[7, 8] = hx
    Gr[8, 6] = hy
    Gr[8, 7] = -hx
    A = np.dot(Gr, np.eye(N) - np.dot(K, H))
    GK = np.dot(Gr, K)
    Pn = np.dot(np.dot(A, P), A.T)
    Pn += np.dot(GK * r, GK.T)
    symmetrise(Pn)
    P[:, :] = Pn
    return dx


@njit
def inject(x: State, dx: np.ndarray) -> State:
    """The nominal state corrected by dx (Sola eq. 282-283): q = q exp(dtheta), renormalised."""
    q = q_mul((x[6], x[7], x[8], x[9]), q_exp((dx[6], dx[7], dx[8])))
    n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (x[0] + dx[0], x[1] + dx[1], x[2] + dx[2],
            x[3] + dx[3], x[4] + dx[4], x[5] + dx[5],
            q[0] * n, q[1] * n, q[2] * n, q[3] * n,
            x[10] + dx[9], x[11] + dx[10], x[12] + dx[11],
            x[13] + dx[12], x[14] + dx[13], x[15] + dx[14])


@njit
def _np_max(a: float, b: float) -> float:
    """np.maximum: NaN if either is NaN."""
    if math.isnan(a) or math.isnan(b):
        return math.nan
    return a if a >= b else b


@njit
def bound_covariance(P: np.ndarray, var_min: np.ndarray, var_max: float) -> None:
    """Diagonal floors and the var_max clamp, in place (row/column scaling keeps P SPD)."""
    _floor_diagonal(P, var_min)
    _clamp_variances(P, var_max)


@njit
def _floor_diagonal(P: np.ndarray, var_min: np.ndarray) -> None:
    """Each variance raised to its floor, when one is below it."""
    n = P.shape[0]
    low = False
    for i in range(n):
        if P[i, i] < var_min[i]:
            low = True
    if low:
        for i in range(n):
            P[i, i] = _np_max(P[i, i], var_min[i])


@njit
def _clamp_variances(P: np.ndarray, var_max: float) -> None:
    """When a variance is above var_max, rows and columns scaled by sqrt(min(1, var_max /
    P_ii)) each (np.sqrt(np.minimum(1.0, v)), NaN kept)."""
    n = P.shape[0]
    high = False
    for i in range(n):
        if P[i, i] > var_max:
            high = True
    if high:
        k = np.empty(n)
        for i in range(n):
            v = var_max / _np_max(P[i, i], 1e-300)
            if math.isnan(v):  # np.sqrt(np.minimum(1.0, v))
                k[i] = math.nan
            elif v > 1.0:
                k[i] = 1.0
            else:
                k[i] = math.sqrt(v)
        for i in range(n):
            for j in range(n):
                P[i, j] = P[i, j] * k[i] * k[j]


@njit
def reset_block(x: np.ndarray, xi: int, P: np.ndarray, i0: int, z: np.ndarray,
                r: float) -> None:
    """EKF2-style reset to the pose, in place: the position (i0 = 0; z its 3 values) or
    attitude (i0 = 6; z the quaternion) of the state at x[xi:] set to z, its covariance rows
    and columns cleared to r I."""
    if i0 == 0:
        for k in range(3):
            x[xi + k] = z[k]
    else:
        for k in range(4):
            x[xi + 6 + k] = z[k]
    for a in range(3):
        for j in range(P.shape[0]):
            P[i0 + a, j] = 0.0
            P[j, i0 + a] = 0.0
    for a in range(3):
        for b in range(3):
            P[i0 + a, i0 + b] = (1.0 if a == b else 0.0) * r
