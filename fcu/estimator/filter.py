"""The filter's compiled kernels on its flat buffers: prediction, the covariance step, the
fusion's bookkeeping and the output predictor (its values and the health verdict are read by
`fcu.estimator.readout`).

Buffers (`fcu.estimator.layouts`): `fb` floats (EF_*: states, the pose under way, the settings
the kernels read), `ib` integers (EI_*: times in us, counters, the ring and queue lengths),
`M` the covariance P (M[0]) and the transition F (M[1]), the ring of buffered IMU samples
(`pend_t` times, `pend_v` gyro and accel), the pose queue by capture time (`pose_c`
captures, `pose_v` p, q and the variances as sent). `fcu.estimator.ekf.Estimator` owns them
and calls them; a pose's fusion is one call (`fuse`). The arithmetic is that of the
interpreted filter, in its order (no fastmath): the same floats, but for the inverse of the
innovation covariance (`fcu.estimator.update.spd_inverse`) and the products that use the
matrices' structure, F P F^T (`fcu.estimator.strapdown.f_p_ft`) and the Joseph update
(`fcu.estimator.update.joseph_apply`), each within 1e-13 relative of numpy's dense products
(tests/unit/test_estimator_kernels.py).
"""

from __future__ import annotations

import numpy as np

from common.jit import njit
from common.quaternion import q_conj, q_log, q_mul
from fcu.estimator.layouts import (
    EF_ACC_B2,
    EF_ACC_N2,
    EF_C_DT2,
    EF_C_X,
    EF_G,
    EF_GATE2,
    EF_GYRO_B2,
    EF_GYRO_N2,
    EF_H_X,
    EF_INNOV,
    EF_LAST_W,
    EF_O_X,
    EF_POSE,
    EF_R,
    EF_R_ATT_FLOOR,
    EF_R_POS_FLOOR,
    EF_RATIO,
    EF_VAR_MAX,
    EF_VAR_MIN,
    EF_XB,
    EI_C_T,
    EI_COV_US,
    EI_DELAY_US,
    EI_DT_US,
    EI_FUSED,
    EI_FUSING,
    EI_H_T,
    EI_LAST_ATT_FUSE,
    EI_LAST_CAPTURE,
    EI_LAST_FUSION,
    EI_LAST_POS_FUSE,
    EI_N_PRED,
    EI_O_T,
    EI_PEND_HEAD,
    EI_PEND_N,
    EI_POSE_C,
    EI_POSE_IGNORED,
    EI_POSES_N,
    EI_QUEUE_MAX,
    EI_REJ_ROW,
    EI_REJECTED,
    EI_REPROPAGATE,
    EI_RESETS,
    EI_RESYNC_T,
    EI_RESYNC_US,
    EI_TIMEOUT_US,
)
from fcu.estimator.output import corrected_output, propagate
from fcu.estimator.strapdown import (
    F_IDX,
    N,
    f_p_ft,
    load_state,
    store_state,
    strapdown,
    transition_entries,
)
from fcu.estimator.update import (
    bound_covariance,
    inject,
    joseph_apply,
    joseph_gain,
    reset_block,
    spd_inverse,
    symmetrise,
)

# imu_step's mode bits and return codes
PUSH = 1  # buffer the sample first
OUTPUT = 2  # then carry the output state to it
DONE = 0
GROW = 1  # the ring is full: grow it and call again
FUSE = 2  # a pose is due at the horizon (fb[EF_POSE], ib[EI_POSE_C]): fuse it, call again
# fuse_begin's verdict bits
OK_POS = 1
OK_ATT = 2


@njit
def cov_step(fb: np.ndarray, ib: np.ndarray, M: np.ndarray) -> None:
    """P = F P F^T + Q over the samples since the last step (Sola eq. 269-274): F's entries
    from `transition_entries`, per-sample IMU noise summed over the interval's dt^2, bias
    random walks over T; every 8th step symmetrised and bounded."""
    T = (ib[EI_H_T] - ib[EI_C_T]) * 1e-6
    if T <= 0.0:
        return
    P = M[0]
    F = M[1]
    e = transition_entries(load_state(fb, EF_C_X), load_state(fb, EF_H_X), T, fb[EF_G])
    for k in range(F_IDX.shape[0]):
        i = F_IDX[k]
        F[i // N, i % N] = e[k]
    qa = fb[EF_ACC_N2] * fb[EF_C_DT2]
    qg = fb[EF_GYRO_N2] * fb[EF_C_DT2]
    qbg = fb[EF_GYRO_B2] * T
    qba = fb[EF_ACC_B2] * T
    Pn = f_p_ft(F, P)
    for i in range(3):
        Pn[i, i] += 0.0
        Pn[3 + i, 3 + i] += qa
        Pn[6 + i, 6 + i] += qg
        Pn[9 + i, 9 + i] += qbg
        Pn[12 + i, 12 + i] += qba
    ib[EI_N_PRED] += 1
    if ib[EI_N_PRED] & 7 == 0:
        symmetrise(Pn)
        bound_covariance(Pn, fb[EF_VAR_MIN:EF_VAR_MIN + N], fb[EF_VAR_MAX])
    P[:, :] = Pn
    for k in range(16):
        fb[EF_C_X + k] = fb[EF_H_X + k]
    ib[EI_C_T] = ib[EI_H_T]
    fb[EF_C_DT2] = 0.0


@njit
def _predict(fb: np.ndarray, ib: np.ndarray, M: np.ndarray, t: int, v: np.ndarray) -> None:
    """The horizon state over one sample (Sola eq. 260); covariance every cov_period_s."""
    dt = (t - ib[EI_H_T]) * 1e-6
    x = strapdown(load_state(fb, EF_H_X), (v[0], v[1], v[2]), (v[3], v[4], v[5]), dt, fb[EF_G])
    store_state(fb, EF_H_X, x)
    ib[EI_H_T] = t
    fb[EF_C_DT2] += dt * dt
    if ib[EI_H_T] - ib[EI_C_T] >= ib[EI_COV_US]:
        cov_step(fb, ib, M)


@njit
def _pop_pose(fb: np.ndarray, ib: np.ndarray, pose_c: np.ndarray, pose_v: np.ndarray) -> int:
    """The oldest queued pose into the pose under way; returns its capture time."""
    c: int = pose_c[0]
    for k in range(9):
        fb[EF_POSE + k] = pose_v[0, k]
    n = ib[EI_POSES_N] - 1
    for j in range(n):
        pose_c[j] = pose_c[j + 1]
        pose_v[j, :] = pose_v[j + 1, :]
    ib[EI_POSES_N] = n
    ib[EI_POSE_C] = c
    return c


@njit
def imu_step(fb: np.ndarray, ib: np.ndarray, M: np.ndarray, pend_t: np.ndarray,
             pend_v: np.ndarray, pose_c: np.ndarray, pose_v: np.ndarray, t: int, w0: float,
             w1: float, w2: float, f0: float, f1: float, f2: float, dt_us: int,
             mode: int) -> int:
    """One IMU sample (t, w, f), the newest (PUSH: buffer it first): the horizon advances
    over the buffered samples up to t - pose_delay, fusing each queued pose when it is due
    (returns FUSE with the pose under way; call again without PUSH once it is fused), then
    (OUTPUT) the output state integrates the sample. GROW: the ring is full, nothing done."""
    ib[EI_DT_US] = dt_us
    if mode & PUSH and not _push(fb, ib, pend_t, pend_v, t, w0, w1, w2, f0, f1, f2):
        return GROW
    if _advance_horizon(fb, ib, M, pend_t, pend_v, pose_c, pose_v, t, dt_us) == FUSE:
        return FUSE
    if mode & OUTPUT:
        _output(fb, ib, t, w0, w1, w2, f0, f1, f2)
    return DONE


@njit
def _push(fb: np.ndarray, ib: np.ndarray, pend_t: np.ndarray, pend_v: np.ndarray, t: int,
          w0: float, w1: float, w2: float, f0: float, f1: float, f2: float) -> bool:
    """The sample buffered in the ring (False: the ring is full) and kept as the newest
    gyro sample."""
    cap = pend_t.shape[0]
    if ib[EI_PEND_N] == cap:
        return False
    j = (ib[EI_PEND_HEAD] + ib[EI_PEND_N]) % cap
    pend_t[j] = t
    pend_v[j, 0] = w0
    pend_v[j, 1] = w1
    pend_v[j, 2] = w2
    pend_v[j, 3] = f0
    pend_v[j, 4] = f1
    pend_v[j, 5] = f2
    ib[EI_PEND_N] += 1
    fb[EF_LAST_W] = w0
    fb[EF_LAST_W + 1] = w1
    fb[EF_LAST_W + 2] = w2
    return True


@njit
def _advance_horizon(fb: np.ndarray, ib: np.ndarray, M: np.ndarray, pend_t: np.ndarray,
                     pend_v: np.ndarray, pose_c: np.ndarray, pose_v: np.ndarray, t: int,
                     dt_us: int) -> int:
    """The horizon predicted over the buffered samples up to t - pose_delay; FUSE as soon
    as a queued pose is due (its capture time reached), DONE when none is left to do."""
    h_lim = t - ib[EI_DELAY_US]
    half = dt_us >> 1
    while True:
        if ib[EI_FUSING]:
            while ib[EI_POSES_N] > 0 and pose_c[0] <= ib[EI_H_T] + half:
                c = _pop_pose(fb, ib, pose_c, pose_v)
                if c <= ib[EI_LAST_CAPTURE]:
                    ib[EI_POSE_IGNORED] += 1
                    continue
                return FUSE
            ib[EI_FUSING] = 0
        if ib[EI_PEND_N] > 0:
            head = ib[EI_PEND_HEAD]
            if pend_t[head] <= h_lim:
                ib[EI_PEND_HEAD] = (head + 1) % pend_t.shape[0]
                ib[EI_PEND_N] -= 1
                _predict(fb, ib, M, pend_t[head], pend_v[head])
                if ib[EI_POSES_N] > 0 and pose_c[0] <= ib[EI_H_T] + half:
                    ib[EI_FUSING] = 1
                continue
        break
    return DONE


@njit
def _output(fb: np.ndarray, ib: np.ndarray, t: int, w0: float, w1: float, w2: float,
            f0: float, f1: float, f2: float) -> None:
    """The output state at t: the horizon's when nothing is buffered beyond it, else
    integrated over the newest sample."""
    if ib[EI_PEND_N] == 0:
        for k in range(16):
            fb[EF_O_X + k] = fb[EF_H_X + k]
        ib[EI_O_T] = ib[EI_H_T]
    elif ib[EI_O_T] < t:
        x = strapdown(load_state(fb, EF_O_X), (w0, w1, w2), (f0, f1, f2),
                      (t - ib[EI_O_T]) * 1e-6, fb[EF_G])
        store_state(fb, EF_O_X, x)
        ib[EI_O_T] = t


@njit
def pose_step(fb: np.ndarray, ib: np.ndarray, pose_c: np.ndarray, pose_v: np.ndarray,
              c: int, v: np.ndarray, dt_us: int) -> int:
    """A checked pose (capture c, values v as in pose_v) once aligned: ignored behind the
    horizon (0), due at the horizon (FUSE: it is the pose under way), or queued (0)."""
    half = dt_us >> 1
    h_t = ib[EI_H_T]
    if c < h_t - half or c <= ib[EI_LAST_CAPTURE]:
        ib[EI_POSE_IGNORED] += 1
        return DONE
    if c <= h_t + half:
        for k in range(9):
            fb[EF_POSE + k] = v[k]
        ib[EI_POSE_C] = c
        return FUSE
    queue_pose(ib, pose_c, pose_v, c, v)
    return DONE


@njit
def queue_pose(ib: np.ndarray, pose_c: np.ndarray, pose_v: np.ndarray, c: int,
               v: np.ndarray) -> None:
    """Insert by capture time, after equal ones (bisect.insort); beyond pose_queue_max the
    oldest is dropped and counted as ignored."""
    j = ib[EI_POSES_N]
    while j > 0 and pose_c[j - 1] > c:
        pose_c[j] = pose_c[j - 1]
        pose_v[j, :] = pose_v[j - 1, :]
        j -= 1
    pose_c[j] = c
    pose_v[j, :] = v
    n = ib[EI_POSES_N] + 1
    if n > ib[EI_QUEUE_MAX]:
        for k in range(n - 1):
            pose_c[k] = pose_c[k + 1]
            pose_v[k, :] = pose_v[k + 1, :]
        n -= 1
        ib[EI_POSE_IGNORED] += 1
    ib[EI_POSES_N] = n


@njit
def _gate(y: tuple[float, float, float], d: np.ndarray, i0: int, g2: float,
          r: float) -> float:
    """max over axes of y^2 / (gate^2 (P_ii + r)), as Python's max (NaN first stays)."""
    m: float = y[0] * y[0] / (g2 * (d[i0, i0] + r))
    for i in range(1, 3):
        v = y[i] * y[i] / (g2 * (d[i0 + i, i0 + i] + r))
        if v > m:
            m = v
    return m


@njit
def fuse_begin(fb: np.ndarray, ib: np.ndarray, M: np.ndarray) -> int:
    """The pose under way at the horizon: covariance step, innovations (position, and the
    attitude's log(q_hat* q)), the variances (the sender's, floored; NaN: the floor), the
    gates; returns OK_POS | OK_ATT for the parts that pass."""
    ib[EI_LAST_CAPTURE] = ib[EI_POSE_C]
    cov_step(fb, ib, M)
    for k in range(16):
        fb[EF_XB + k] = fb[EF_H_X + k]
    x = fb[EF_H_X:EF_H_X + 16]
    z = fb[EF_POSE:EF_POSE + 9]
    yp = (z[0] - x[0], z[1] - x[1], z[2] - x[2])
    ya = q_log(q_mul(q_conj((x[6], x[7], x[8], x[9])), (z[3], z[4], z[5], z[6])))
    r_p = z[7] if z[7] > fb[EF_R_POS_FLOOR] else fb[EF_R_POS_FLOOR]
    r_a = z[8] if z[8] > fb[EF_R_ATT_FLOOR] else fb[EF_R_ATT_FLOOR]
    P = M[0]
    g2 = fb[EF_GATE2]
    tr_p = _gate(yp, P, 0, g2, r_p)
    tr_a = _gate(ya, P, 6, g2, r_a)
    for k in range(3):
        fb[EF_INNOV + k] = yp[k]
        fb[EF_INNOV + 3 + k] = ya[k]
    fb[EF_R] = r_p
    fb[EF_R + 1] = r_a
    fb[EF_RATIO] = tr_p
    fb[EF_RATIO + 1] = tr_a
    return (OK_POS if tr_p <= 1.0 else 0) | (OK_ATT if tr_a <= 1.0 else 0)


@njit
def apply_update(fb: np.ndarray, M: np.ndarray, idx: np.ndarray, pht: np.ndarray,
                 s_inv: np.ndarray, y: np.ndarray, r: np.ndarray) -> None:
    """The update's second half (`joseph_apply`), the injection into the horizon state and
    the covariance's bounds."""
    dx = joseph_apply(M[0], idx, pht, s_inv, y, r)
    store_state(fb, EF_H_X, inject(load_state(fb, EF_H_X), dx))
    bound_covariance(M[0], fb[EF_VAR_MIN:EF_VAR_MIN + N], fb[EF_VAR_MAX])


@njit
def _measurement(fb: np.ndarray, pos: bool, att: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(idx, y, r) of the parts of the pose under way that passed their gates: idx the rows
    of I15 they measure (H: position 0-2, attitude 6-8), the innovations, the variances."""
    m = 3 * (int(pos) + int(att))
    idx = np.empty(m, dtype=np.int64)
    y = np.empty(m)
    r = np.empty(m)
    i = 0
    for part, col, innov, var in ((pos, 0, EF_INNOV, EF_R), (att, 6, EF_INNOV + 3, EF_R + 1)):
        if part:
            for k in range(3):
                idx[i + k] = col + k
                y[i + k] = fb[innov + k]
                r[i + k] = fb[var]
            i += 3
    return idx, y, r


@njit
def fuse(fb: np.ndarray, ib: np.ndarray, M: np.ndarray, pend_t: np.ndarray,
         pend_v: np.ndarray) -> int:
    """The pose under way at the horizon, in one call: `fuse_begin` (gates), the Joseph
    update of the parts that pass (`joseph_gain`, `spd_inverse`, `apply_update`), then
    `fuse_end`. Returns the verdict bits; 0 when S was not positive definite (nothing is
    fused, and it counts as a rejection)."""
    ok = fuse_begin(fb, ib, M)
    if ok:
        idx, y, r = _measurement(fb, (ok & OK_POS) != 0, (ok & OK_ATT) != 0)
        pht, S = joseph_gain(M[0], idx, r)
        spd, s_inv = spd_inverse(S)
        if spd:
            apply_update(fb, M, idx, pht, s_inv, y, r)
        else:
            ok = 0
    fuse_end(fb, ib, M, pend_t, pend_v, ok)
    return ok


@njit
def repropagate(fb: np.ndarray, ib: np.ndarray, pend_t: np.ndarray,
                pend_v: np.ndarray) -> None:
    """Output = horizon state propagated over the buffered samples (output predictor)."""
    x, t = propagate(load_state(fb, EF_H_X), ib[EI_H_T], pend_t, pend_v, ib[EI_PEND_HEAD],
                     ib[EI_PEND_N], fb[EF_G])
    store_state(fb, EF_O_X, x)
    ib[EI_O_T] = t


@njit
def _correct_output(fb: np.ndarray, ib: np.ndarray, pend_t: np.ndarray, pend_v: np.ndarray,
                    exact: bool) -> None:
    """Carry the horizon's correction (xb -> h_x) to the output state: linearised over the
    buffered interval (`corrected_output`); exact re-propagation after a reset, with
    output_repropagate, and every output_resync_s."""
    o_t, h_t = ib[EI_O_T], ib[EI_H_T]
    if o_t < h_t:
        return
    if (exact or o_t == h_t or ib[EI_REPROPAGATE] != 0
            or h_t - ib[EI_RESYNC_T] >= ib[EI_RESYNC_US]):
        repropagate(fb, ib, pend_t, pend_v)
        ib[EI_RESYNC_T] = h_t
        return
    x = corrected_output(load_state(fb, EF_XB), load_state(fb, EF_H_X),
                         load_state(fb, EF_O_X), (o_t - h_t) * 1e-6, fb[EF_G])
    store_state(fb, EF_O_X, x)


@njit
def fuse_end(fb: np.ndarray, ib: np.ndarray, M: np.ndarray, pend_t: np.ndarray,
             pend_v: np.ndarray, ok: int) -> None:
    """After the update (if any part passed): the counters, the resets to the pose after
    pose_reset_timeout_s of refusals, the output's correction."""
    c = ib[EI_POSE_C]
    ok_p = (ok & OK_POS) != 0
    ok_a = (ok & OK_ATT) != 0
    reset = False
    if ok_p:
        ib[EI_LAST_POS_FUSE] = c
    if ok_a:
        ib[EI_LAST_ATT_FUSE] = c
    if ok_p or ok_a:
        ib[EI_LAST_FUSION] = c
    if ok_p and ok_a:
        ib[EI_FUSED] += 1
        ib[EI_REJ_ROW] = 0
    else:
        ib[EI_REJECTED] += 1
        ib[EI_REJ_ROW] += 1
        timeout = ib[EI_TIMEOUT_US]
        if not ok_p and c - ib[EI_LAST_POS_FUSE] > timeout:
            reset_block(fb, EF_H_X, M[0], 0, fb[EF_POSE:EF_POSE + 3], fb[EF_R])
            ib[EI_RESETS] += 1
            ib[EI_REJ_ROW] = 0
            ib[EI_LAST_POS_FUSE] = c
            reset = True
        if not ok_a and c - ib[EI_LAST_ATT_FUSE] > timeout:
            reset_block(fb, EF_H_X, M[0], 6, fb[EF_POSE + 3:EF_POSE + 7], fb[EF_R + 1])
            ib[EI_RESETS] += 1
            ib[EI_REJ_ROW] = 0
            ib[EI_LAST_ATT_FUSE] = c
            reset = True
    if ok_p or ok_a or reset:
        _correct_output(fb, ib, pend_t, pend_v, reset)
