"""What the filter's buffers say, read by compiled kernels (`fcu.estimator.filter`'s
buffers, `fcu.estimator.layouts`): the output state's values, the health verdict from the
largest variances, the standard deviations of the status and its positive-definiteness test.
Same arithmetic and order as the interpreted reads they replace (no fastmath), but for that
test's factorisation (`positive_definite`).
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit
from common.quaternion import q_rotate_inv
from fcu.estimator.layouts import (
    EF_CONVERGED_VAR,
    EF_HEALTHY_VAR,
    EF_LAST_W,
    EF_O_X,
    EF_SD,
    EI_O_T,
)
from fcu.estimator.strapdown import N
from fcu.estimator.update import cholesky_lower


@njit
def output_values(fb: np.ndarray, ib: np.ndarray) -> tuple[
        int, tuple[float, float, float], tuple[float, float, float, float],
        tuple[float, float, float], tuple[float, float, float]]:
    """(t_us, p, q, v_flu, bias-corrected rate) of the output state."""
    x = fb[EF_O_X:EF_O_X + 16]
    q = (x[6], x[7], x[8], x[9])
    w = fb[EF_LAST_W:EF_LAST_W + 3]
    return (ib[EI_O_T], (x[0], x[1], x[2]), q, q_rotate_inv(q, (x[3], x[4], x[5])),
            (w[0] - x[10], w[1] - x[11], w[2] - x[12]))


@njit
def variance_code(fb: np.ndarray, M: np.ndarray) -> int:
    """health()'s verdict from the largest variances of position, velocity and attitude (no
    Cholesky test): 0 neither, 1 healthy, 3 healthy and converged. The finite test sums in
    Python's order (math.isfinite(sum(list)))."""
    P = M[0]
    sd = 0.0
    lo = P[0, 0]
    for i in range(N):
        sd += P[i, i]
        if P[i, i] < lo:
            lo = P[i, i]
    sx = 0.0
    for k in range(16):
        sx += fb[EF_O_X + k]
    if not (math.isfinite(sd) and math.isfinite(sx) and lo > 0.0):
        return 0
    v = np.empty(3)
    for b in range(3):
        m = P[3 * b, 3 * b]
        for i in range(1, 3):
            if P[3 * b + i, 3 * b + i] > m:
                m = P[3 * b + i, 3 * b + i]
        v[b] = m
    hv = fb[EF_HEALTHY_VAR:EF_HEALTHY_VAR + 3]
    cv = fb[EF_CONVERGED_VAR:EF_CONVERGED_VAR + 3]
    healthy = v[0] < hv[0] and v[1] < hv[1] and v[2] < hv[2]
    if not healthy:
        return 0
    if v[0] < cv[0] and v[1] < cv[1] and v[2] < cv[2]:
        return 3
    return 1


@njit
def sd_values(fb: np.ndarray, M: np.ndarray) -> bool:
    """status()'s standard deviations into fb[EF_SD:] (sqrt of the diagonal floored at 0;
    inf when P or the output state is not finite; np.maximum's -0.0 kept); returns whether
    both are finite."""
    P = M[0]
    finite = True
    for i in range(N):
        for j in range(N):
            if not math.isfinite(P[i, j]):
                finite = False
    for k in range(16):
        if not math.isfinite(fb[EF_O_X + k]):
            finite = False
    for i in range(N):
        d = P[i, i]
        fb[EF_SD + i] = math.sqrt(d if d >= 0.0 else 0.0) if finite else math.inf
    return finite


@njit
def positive_definite(M: np.ndarray) -> bool:
    """Whether the covariance P = M[0], symmetrised ((P + P^T) / 2, as numpy computes it),
    has a Cholesky factor (`update.cholesky_lower`). numpy's LAPACK factorises in another
    order, so the two verdicts can differ only for a P whose smallest pivot is within
    rounding of zero (tests/unit/test_estimator_kernels.py compares them)."""
    P = M[0]
    n = P.shape[0]
    S = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            S[i, j] = 0.5 * (P[i, j] + P[j, i])
    return cholesky_lower(S, np.zeros((n, n)))
