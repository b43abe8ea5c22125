"""The estimator's compiled kernels (fcu/estimator/filter.py, update.py, strapdown.py,
output.py) against references written here: straightforward numpy for the maths (a dropped
or wrong term shows as a difference far above rounding), and numpy in the interpreted
filter's own order for the bits (the kernels must give the same floats), but for the
products written over the matrices' structure (F P F^T, the Joseph update), which must
agree with numpy's dense products within 1e-13 relative."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fcu.estimator import buffers
from fcu.estimator.buffers import filter_buffers
from fcu.estimator.ekf import Estimator
from fcu.estimator.filter import cov_step
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.estimator.layouts import (
    EF_C_DT2,
    EF_C_X,
    EF_H_X,
    EF_O_X,
    EF_SD,
    EF_VAR_MAX,
    EF_VAR_MIN,
    EI_C_T,
    EI_H_T,
    EI_N_PRED,
)
from fcu.estimator.readout import positive_definite, sd_values, variance_code
from fcu.estimator.settings import EstimatorSettings
from fcu.estimator.strapdown import F_COLS, F_IDX, f_p_ft, strapdown
from fcu.estimator.update import (
    bound_covariance,
    inject,
    joseph_apply,
    joseph_gain,
    spd_inverse,
)

RNG_SEED = 20261203
I15 = np.eye(15)
H_POS = I15[[0, 1, 2]]  # the measurement selectors the filter builds (`filter._measurement`)
H_ATT = I15[[6, 7, 8]]
H_BOTH = I15[[0, 1, 2, 6, 7, 8]]
STRUCTURED_REL = 1e-13  # the structured products against numpy's dense ones


def _rows(H: np.ndarray) -> np.ndarray:
    """The rows of I15 a selector H takes (the kernels' `idx`)."""
    return np.flatnonzero(H.any(axis=0)).astype(np.int64)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rot(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[0] * b[0] - a[1:] @ b[1:],
                     *(a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:]))])


def _qexp(r: np.ndarray) -> np.ndarray:
    h = 0.5 * np.linalg.norm(r)
    if h == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.array([math.cos(h), *(math.sin(h) * r / (2 * h))])


def _random_state(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return np.concatenate([rng.normal(size=3), rng.normal(size=3), q,
                           rng.normal(0, 0.01, 3), rng.normal(0, 0.1, 3)])


def _spd(rng: np.random.Generator, n: int = 15) -> np.ndarray:
    a = rng.normal(size=(n, n)) * 1e-2
    return a @ a.T + 1e-6 * np.eye(n)


def test_strapdown_against_a_numpy_reference():
    """Given random states and samples, then the compiled strapdown is the textbook step
    (mid-interval specific force in the world frame, p += v dt + a dt^2/2, v += a dt,
    q = q exp(w dt)) within rounding, and its interpreted source to the bit."""
    rng = np.random.default_rng(RNG_SEED)
    g = 9.81
    for _ in range(200):
        x = _random_state(rng)
        w, f = rng.normal(0, 2, 3), rng.normal(0, 10, 3)
        dt = rng.uniform(1e-4, 5e-3)
        got = np.array(strapdown(tuple(x), tuple(w), tuple(f), dt, g))
        assert tuple(got) == strapdown.py_func(tuple(x), tuple(w), tuple(f), dt, g)
        r = (w - x[10:13]) * dt
        a = f - x[13:16]
        a_mid = a + 0.5 * np.cross(r, a)  # the force rotated to mid-interval
        a_w = _rot(x[6:10]) @ a_mid - np.array([0.0, 0.0, g])
        q = _qmul(x[6:10], _qexp(r))
        ref = np.concatenate([x[0:3] + x[3:6] * dt + 0.5 * a_w * dt * dt, x[3:6] + a_w * dt,
                              q / np.linalg.norm(q), x[10:16]])
        assert np.abs(got - ref).max() < 1e-12


def _transition_reference(x0: np.ndarray, x1: np.ndarray, T: float, g: float) -> np.ndarray:
    """F from the package docstring's blocks (mid-interval attitude, dV the interval's
    world specific-force integral)."""
    qm = x0[6:10] + x1[6:10]
    R = _rot(qm / np.linalg.norm(qm))
    dV = x1[3:6] - x0[3:6] + np.array([0.0, 0.0, g * T])
    dth = 2.0 * _qmul(np.array([x0[6], *-x0[7:10]]), x1[6:10])[1:]
    M = _skew(dV) @ R
    F = np.eye(15)
    F[0:3, 3:6] = T * np.eye(3)
    F[0:3, 6:9] = -0.5 * T * M
    F[0:3, 12:15] = -0.5 * T * T * R
    F[3:6, 6:9] = -M
    F[3:6, 9:12] = 0.5 * T * M
    F[3:6, 12:15] = -T * R
    F[6:9, 6:9] = np.eye(3) - _skew(dth)
    F[6:9, 9:12] = -T * np.eye(3)
    return F


def test_covariance_step_against_a_numpy_reference():
    """Given random interval end states and covariances, then the compiled covariance step
    is F P F^T + Q (noise over the interval's dt^2, bias walks over T) within rounding."""
    rng = np.random.default_rng(RNG_SEED + 1)
    st = EstimatorSettings()
    for k in range(100):
        fb, ib, M, *_ = filter_buffers(st)
        x0, x1 = _random_state(rng), _random_state(rng)
        x1[6:10] = x0[6:10] + rng.normal(0, 0.01, 4)  # a small turn over the interval
        x1[6:10] /= np.linalg.norm(x1[6:10])
        T, dt2 = 0.01, 10 * 1e-6
        fb[EF_C_X:EF_C_X + 16], fb[EF_H_X:EF_H_X + 16], fb[EF_C_DT2] = x0, x1, dt2
        ib[EI_C_T], ib[EI_H_T] = 0, 10_000
        ib[EI_N_PRED] = k % 8  # every 8th step is symmetrised and bounded too
        P = _spd(rng)
        M[0] = P
        cov_step(fb, ib, M)
        F = _transition_reference(x0, x1, T, st.gravity_m_s2)
        q = np.array([0.0] * 3 + [st.accel_noise_m_s2 ** 2 * dt2] * 3
                     + [st.gyro_noise_rad_s ** 2 * dt2] * 3
                     + [st.gyro_bias_noise_rad_s2 ** 2 * T] * 3
                     + [st.accel_bias_noise_m_s3 ** 2 * T] * 3)
        ref = F @ P @ F.T + np.diag(q)
        assert np.abs(M[1] - F).max() < 1e-12
        assert np.abs(M[0] - ref).max() < 1e-12 * np.abs(ref).max()
        assert list(fb[EF_C_X:EF_C_X + 16]) == list(x1) and fb[EF_C_DT2] == 0.0


def _update_reference(P: np.ndarray, H: np.ndarray, y: np.ndarray, r: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Textbook Joseph form with the attitude reset G = I - [dtheta/2]x: K from a solve."""
    S = H @ P @ H.T + np.diag(r)
    K = np.linalg.solve(S, H @ P).T
    dx = K @ y
    G = np.eye(15)
    G[6:9, 6:9] -= _skew(0.5 * dx[6:9])
    A = np.eye(15) - K @ H
    Pn = G @ (A @ P @ A.T + K @ np.diag(r) @ K.T) @ G.T
    return 0.5 * (Pn + Pn.T), dx


def _update_numpy_order(P: np.ndarray, H: np.ndarray, y: list[float], r: list[float]
                        ) -> tuple[np.ndarray, list[float]]:
    """The interpreted filter's update, operation for operation (numpy's dot, inv)."""
    pht = P.dot(H.T)
    S = H.dot(pht)
    S.flat[::len(r) + 1] += r
    K = pht.dot(np.linalg.inv(S))
    dx = K.dot(y).tolist()
    hx, hy, hz = 0.5 * dx[6], 0.5 * dx[7], 0.5 * dx[8]
    Gr = np.eye(15)
    Gr.flat[[6 * 15 + 7, 6 * 15 + 8, 7 * 15 + 6, 7 * 15 + 8, 8 * 15 + 6, 8 * 15 + 7]] = \
        (hz, -hy, -hz, hx, hy, -hx)
    A = Gr.dot(np.eye(15) - K.dot(H))
    GK = Gr.dot(K)
    P = A.dot(P).dot(A.T)
    P += (GK * r).dot(GK.T)
    P += P.T
    P *= 0.5
    return P, dx


@pytest.mark.parametrize("H", [H_BOTH, H_POS, H_ATT], ids=["both", "position", "attitude"])
def test_update_against_references(H):
    """Given random covariances, innovations and variances, then the compiled update (its
    two halves around the compiled inverse) is the textbook Joseph update with the reset
    within rounding; its first half (P H^T, S) is numpy's dense products to the bit, and,
    given numpy's inverse, the whole is the interpreted filter's numpy update within
    1e-13 relative (the structured sums in another order)."""
    rng = np.random.default_rng(RNG_SEED + 2)
    m = H.shape[0]
    idx = _rows(H)
    worst = 0.0
    for _ in range(200):
        P = _spd(rng)
        y = rng.normal(0, 0.01, m)
        r = rng.uniform(1e-6, 1e-4, m)
        Pk = P.copy()
        pht, S = joseph_gain(Pk, idx, r)
        pht_np = P.dot(H.T)
        S_np = H.dot(pht_np)
        S_np.flat[::m + 1] += r
        assert np.array_equal(pht, pht_np) and np.array_equal(S, S_np)
        dx = joseph_apply(Pk, idx, pht, np.linalg.inv(S), y, r)
        P_np, dx_np = _update_numpy_order(P.copy(), H, y.tolist(), r.tolist())
        worst = max(worst, float(np.abs(Pk - P_np).max() / np.abs(P_np).max()),
                    float(np.abs(dx - dx_np).max() / np.abs(dx_np).max()))
        assert np.array_equal(Pk, Pk.T)
        Pk = P.copy()
        dx = joseph_apply(Pk, idx, pht, spd_inverse(S)[1], y, r)
        P_ref, dx_ref = _update_reference(P, H, y, r)
        assert np.abs(dx - dx_ref).max() < 1e-12
        assert np.abs(Pk - P_ref).max() < 1e-10 * np.abs(P_ref).max()
    assert worst < STRUCTURED_REL, worst


def test_f_p_ft_is_the_dense_product_within_rounding():
    """Given transitions with random values at F's time-varying entries (F_IDX) and on its
    diagonal, then `F_COLS` holds every entry that can be non-zero and the structured
    F P F^T is numpy's dense product within 1e-13 relative."""
    rng = np.random.default_rng(RNG_SEED + 8)
    mask = np.eye(15, dtype=bool)
    mask.flat[F_IDX] = True
    listed = np.zeros((15, 15), dtype=bool)
    for i, row in enumerate(F_COLS):
        listed[i, row[row >= 0]] = True
    assert np.array_equal(listed, mask)
    worst = 0.0
    for _ in range(300):
        F = np.zeros((15, 15))
        F[mask] = rng.normal(size=int(mask.sum()))
        P = _spd(rng)
        want = F @ P @ F.T
        worst = max(worst, float(np.abs(f_p_ft(F, P) - want).max() / np.abs(want).max()))
    assert worst < STRUCTURED_REL, worst


@pytest.mark.parametrize("H", [H_BOTH, H_POS, H_ATT], ids=["both", "position", "attitude"])
def test_innovation_covariance_inverse_is_numpys_within_rounding(H):
    """Given the innovation covariances of random filter covariances and measurement
    variances from 1e-10 to 1e-2, then the compiled Cholesky inverse is numpy's LAPACK
    inverse within 1e-13 relative, exactly symmetric, and S S^-1 = I within rounding."""
    rng = np.random.default_rng(RNG_SEED + 7)
    m = H.shape[0]
    worst = 0.0
    for _ in range(300):
        P = _spd(rng)
        r = 10.0 ** rng.uniform(-10, -2, m)
        _, S = joseph_gain(P, _rows(H), r)
        ok, inv = spd_inverse(S)
        want = np.linalg.inv(S)
        assert ok and np.array_equal(inv, inv.T)
        worst = max(worst, float(np.abs(inv - want).max() / np.abs(want).max()))
        assert np.abs(S @ inv - np.eye(m)).max() < 1e-9
    assert worst < 1e-13, worst


@pytest.mark.parametrize("S", [np.diag([1.0, -1e-9, 1.0]), np.zeros((3, 3)),
                               np.full((3, 3), np.nan), np.array([[1.0, 2.0], [2.0, 1.0]])],
                         ids=["negative pivot", "zero", "nan", "indefinite"])
def test_inverse_refuses_a_matrix_that_is_not_positive_definite(S):
    ok, inv = spd_inverse(S)
    assert not ok and np.isnan(inv).all()


def _numpy_says_positive_definite(P: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(0.5 * (P + P.T))
    except np.linalg.LinAlgError:
        return False
    return True


def test_status_positive_definiteness_is_numpys_verdict():
    """Given covariances that are positive definite (well and badly conditioned, slightly
    asymmetric), indefinite (one eigenvalue pushed below zero by a margin), singular, with
    then the compiled test on (P + P^T) / 2 says what numpy's LAPACK Cholesky says, for
    each; with a NaN or an infinity it says no (numpy's passes a NaN: status() tests
    finiteness first)."""
    rng = np.random.default_rng(RNG_SEED + 11)
    cases = []
    for _ in range(200):
        P = _spd(rng)
        cases.append(P)
        cases.append(P + rng.normal(0, 1e-9, P.shape))  # asymmetric by rounding-sized noise
        w, v = np.linalg.eigh(P)
        w[rng.integers(15)] = -rng.uniform(1e-6, 1e-2) * w.max()
        cases.append((v * w) @ v.T)  # indefinite
        w[:] = 10.0 ** rng.uniform(-14, 0, 15)  # condition numbers up to 1e14
        cases.append((v * w) @ v.T)
    cases += [np.zeros((15, 15)), np.diag([1.0] * 14 + [0.0]), np.diag([1.0] * 14 + [-1.0])]
    said = [positive_definite(P[None]) for P in cases]
    assert said == [_numpy_says_positive_definite(P) for P in cases]
    assert 0 < sum(said) < len(said)
    for bad in (math.nan, math.inf, -math.inf):
        P = _spd(rng)
        P[3, 5] = bad
        assert not positive_definite(P[None])


def test_injection_and_bounds_against_numpy():
    """Given random corrections and covariances with small, huge and NaN variances, then
    the injection is q exp(dtheta) and the rest added, and the bounds are numpy's floors and
    row/column scaling, to the bit."""
    rng = np.random.default_rng(RNG_SEED + 3)
    var_min = np.array([1e-14] * 9 + [1e-16] * 6)
    for k in range(200):
        x, dx = _random_state(rng), rng.normal(0, 0.01, 15)
        got = np.array(inject(tuple(x), dx))
        q = _qmul(x[6:10], _qexp(dx[6:9]))
        assert np.abs(got[6:10] - q / np.linalg.norm(q)).max() < 1e-14
        assert np.abs(got[[0, 1, 2, 3, 4, 5, 10, 11, 12, 13, 14, 15]]
                      - (x[[0, 1, 2, 3, 4, 5, 10, 11, 12, 13, 14, 15]] + np.delete(
                          dx, [6, 7, 8]))).max() < 1e-15
        P = _spd(rng)
        P[k % 15, k % 15] = (1e-20, 1e9, 1e12, math.nan, -1.0)[k % 5]
        ref = P.copy()
        d = ref.diagonal()
        if (d < var_min).any():
            ref.flat[::16] = np.maximum(d, var_min)
        if (d > 1e8).any():
            s = np.sqrt(np.minimum(1.0, 1e8 / np.maximum(d, 1e-300)))
            ref *= s[:, None]
            ref *= s[None, :]
        bound_covariance(P, var_min, 1e8)
        assert np.array_equal(P, ref, equal_nan=True)


def test_health_and_sd_against_numpy():
    """Given covariances and states, some not finite, then health's verdict and status'
    sd are the interpreted filter's."""
    rng = np.random.default_rng(RNG_SEED + 4)
    st = EstimatorSettings()
    for k in range(100):
        fb, _, M, *_ = filter_buffers(st)
        P = _spd(rng) * 10.0 ** rng.uniform(-8, 2)
        if k % 7 == 3:
            P[2, 2] = math.inf
        if k % 11 == 5:
            fb[EF_O_X + 4] = math.nan
        M[0] = P
        x = fb[EF_O_X:EF_O_X + 16].tolist()
        d = P.diagonal().tolist()
        ok = math.isfinite(sum(d)) and math.isfinite(sum(x)) and min(d) > 0.0
        pv, vv, av = max(d[0:3]), max(d[3:6]), max(d[6:9])
        healthy = ok and (pv < st.healthy_pos_sd_max_m ** 2 and vv < st.healthy_vel_sd_max_m_s
                          ** 2 and av < st.healthy_att_sd_max_rad ** 2)
        converged = healthy and (pv < st.converged_pos_sd_m ** 2 and vv < st.converged_vel_sd_m_s
                                 ** 2 and av < st.converged_att_sd_rad ** 2)
        assert variance_code(fb, M) == (3 if converged else 1 if healthy else 0)
        finite = bool(np.isfinite(P).all()) and all(math.isfinite(v) for v in x)
        assert sd_values(fb, M) == finite
        sd = fb[EF_SD:EF_SD + 15].tolist()
        assert sd == (np.sqrt(np.maximum(P.diagonal(), 0.0)).tolist() if finite
                      else [math.inf] * 15)
    assert fb[EF_VAR_MAX] == st.var_max and fb[EF_VAR_MIN] == 1e-14


def _fly(settings: EstimatorSettings, n: int = 3000) -> list[object]:
    """A seeded hover-and-turn stream with delayed poses; every output and the status."""
    rng = np.random.default_rng(RNG_SEED + 5)
    est = Estimator(settings)
    out: list[object] = []
    delay_us = round(settings.pose_delay_s * 1e6)
    for k in range(1, n + 1):
        t = k * 1000
        yaw = 0.5 if t > 1_500_000 else 0.0
        w, f = rng.normal(0, 0.01, 3), rng.normal(0, 0.1, 3)
        w[2] += yaw
        f[2] += 9.81
        est.on_imu(ImuInput(t, (w[0], w[1], w[2]), (f[0], f[1], f[2])))
        if k % 5 == 0 and t > delay_us:
            c = t - delay_us
            h = 0.25 * max(0.0, c * 1e-6 - 1.5)
            est.on_pose(PoseInput(c, tuple(rng.normal(0, 1e-3, 3)),
                                  (math.cos(h), 0.0, 0.0, math.sin(h))))
        out.append(est.output())
    out.append(est.status())
    out.append(est.covariance.tolist())
    return out


def test_a_long_horizon_grows_the_sample_ring_without_changing_a_figure(monkeypatch):
    """Given a 0.3 s pose delay (300 buffered samples, the ring starts at 64), then every
    output, the status and the covariance are those of a filter whose ring never grows."""
    settings = EstimatorSettings(pose_delay_s=0.3, align_time_s=0.5)
    grown = _fly(settings)
    monkeypatch.setattr(buffers, "RING", 1024)
    assert _fly(settings) == grown
    assert grown[-2].fused > 400  # type: ignore[attr-defined]
