"""The measurement update: Joseph form, injection and reset (Sola sec. 6.2-6.3).

The pose measures position and attitude directly, so H is a selector: the rows `idx` of
I15 (position 0-2, attitude 6-8); the attitude innovation is log(q_hat* q_meas), a local
(body) rotation vector.

Compiled (`common.jit.njit`): `joseph_gain`, the innovation covariance's inverse
(`spd_inverse`, by Cholesky: S is symmetric positive definite), then `joseph_apply`. The
inverse is this module's own rather than LAPACK's, so that a fusion is one compiled call and
its result does not depend on the LAPACK a platform's numpy links; it agrees with numpy's
`np.linalg.inv` within 1e-13 relative on the filter's matrices. The products use H's
structure instead of dense 15x15 matrix products: P H^T and H P H^T are entries of P
(numpy's dense products give these very floats), and the Joseph form is written out as
B = P - K (H P), then B - (B H^T) K^T + K R K^T, and the reset G's 3x3 block applied to
rows and columns 6-8. That is about 5,000 multiplications where the dense form took about
19,000 in ten BLAS calls, and it agrees with the dense form in numpy within 1e-13
relative (tests/unit/test_estimator_kernels.py); the filter's pinned flight figures
(tests/closed_loop/test_reference_figures.py, 1e-9 relative) did not move.
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit
from common.quaternion import q_exp, q_mul
from fcu.estimator.strapdown import State


@njit
def joseph_gain(P: np.ndarray, idx: np.ndarray, r: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(P H^T, S = H P H^T + diag(r)) for H the rows `idx` of I15: the first half of the
    update, entries of P selected."""
    n, m = P.shape[0], idx.shape[0]
    pht = np.empty((n, m))
    for i in range(n):
        for a in range(m):
            pht[i, a] = P[i, idx[a]]
    S = np.empty((m, m))
    for a in range(m):
        for b in range(m):
            S[a, b] = pht[idx[a], b]
        S[a, a] += r[a]
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
def joseph_apply(P: np.ndarray, idx: np.ndarray, pht: np.ndarray, s_inv: np.ndarray,
                 y: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The second half, for H the rows `idx` of I15: K = P H^T S^-1, dx = K y and, in place,
    P = G [(I - K H) P (I - K H)^T + K R K^T] G^T, symmetrised, with the attitude reset
    G = I - [dtheta/2]x (Sola eq. 287); returns dx."""
    n, m = P.shape[0], idx.shape[0]
    K = np.empty((n, m))
    dx = np.empty(n)
    for i in range(n):
        d = 0.0
        for a in range(m):
            t = 0.0
            for b in range(m):
                t += pht[i, b] * s_inv[b, a]
            K[i, a] = t
            d += t * y[a]
        dx[i] = d
    X = _joseph_form(P, idx, K, r)
    _reset_attitude(X, 0.5 * dx[6], 0.5 * dx[7], 0.5 * dx[8])
    symmetrise(X)
    P[:, :] = X
    return dx


@njit
def _joseph_form(P: np.ndarray, idx: np.ndarray, K: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(I - K H) P (I - K H)^T + K R K^T for H the rows `idx` of I15: B = P - K (H P), H P
    the rows idx of P, then B - (B H^T) K^T + K R K^T, B H^T the columns idx of B."""
    n, m = P.shape[0], idx.shape[0]
    B = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            t = P[i, j]
            for a in range(m):
                t -= K[i, a] * P[idx[a], j]
            B[i, j] = t
    X = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            t = B[i, j]
            for a in range(m):
                t += K[j, a] * (r[a] * K[i, a] - B[i, idx[a]])
            X[i, j] = t
    return X


@njit
def _reset_attitude(X: np.ndarray, hx: float, hy: float, hz: float) -> None:
    """X = G X G^T in place, G = I - [h]x on the attitude's rows and columns 6-8 (the
    identity elsewhere)."""
    n = X.shape[0]
    for j in range(n):  # G X: rows 6-8
        a0, a1, a2 = X[6, j], X[7, j], X[8, j]
        X[6, j] = a0 + hz * a1 - hy * a2
        X[7, j] = a1 - hz * a0 + hx * a2
        X[8, j] = a2 + hy * a0 - hx * a1
    for i in range(n):  # (G X) G^T: columns 6-8
        a0, a1, a2 = X[i, 6], X[i, 7], X[i, 8]
        X[i, 6] = a0 + hz * a1 - hy * a2
        X[i, 7] = a1 - hz * a0 + hx * a2
        X[i, 8] = a2 + hy * a0 - hx * a1


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
