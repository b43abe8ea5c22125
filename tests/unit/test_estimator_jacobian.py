"""The estimator's state transition F (`fcu.estimator.strapdown.transition_entries`)
against a central-difference Jacobian of its own strapdown (`strapdown`) over the same IMU
samples, in the error state it defines: dx = [dp, dv, dtheta, db_g, db_a] with
q = q_hat exp(dtheta). A flipped sign or a dropped term in any block keeps P positive
definite and passes every other test; here it differs from the derivative by as much as the
block itself."""

from __future__ import annotations

import numpy as np
import pytest

from common.quaternion import q_conj, q_exp, q_log, q_mul
from fcu.estimator.ekf import Estimator
from fcu.estimator.strapdown import strapdown

DT = 0.0025  # 400 Hz, four samples: EKF2's 10 ms prediction interval
EPS = 1e-6
# (rows, columns) of F's blocks: p, v, theta, b_g, b_a
BLOCKS = {"dp/dv": (0, 3), "dp/dtheta": (0, 6), "dp/db_a": (0, 12), "dv/dtheta": (3, 6),
          "dv/db_g": (3, 9), "dv/db_a": (3, 12), "dtheta/dtheta": (6, 6),
          "dtheta/db_g": (6, 9), "p/p": (0, 0), "v/v": (3, 3), "b_g/b_g": (9, 9),
          "b_a/b_a": (12, 12)}


def _perturb(x: tuple, k: int, e: float) -> tuple:
    """x moved by e along error-state axis k (attitude: q exp(e axis), local)."""
    out = list(x)
    if k < 6:
        out[k] += e
    elif k < 9:
        axis = [0.0, 0.0, 0.0]
        axis[k - 6] = e
        out[6:10] = q_mul(tuple(x[6:10]), q_exp(tuple(axis)))
    else:
        out[k + 1] += e
    return tuple(out)


def _error(x: tuple, ref: tuple) -> np.ndarray:
    """The error state of x about ref."""
    d = np.array(x, dtype=float) - np.array(ref, dtype=float)
    theta = q_log(q_mul(q_conj(tuple(ref[6:10])), tuple(x[6:10])))
    return np.concatenate([d[0:6], theta, d[10:16]])


def _propagate(x: tuple, samples, g: float) -> tuple:
    for w, f in samples:
        x = strapdown(x, w, f, DT, g)
    return x


CASES = [  # (attitude, velocity, gyro, specific force, biases)
    ((0.3, -0.2, 1.1), (1.0, -2.0, 0.5), (0.8, -0.5, 1.2), (1.0, -0.5, 9.9),
     (0.01, -0.02, 0.005, 0.1, -0.05, 0.2)),
    ((2.5, 0.4, -0.7), (-3.0, 0.0, -1.0), (-2.0, 1.5, 0.3), (-4.0, 6.0, 3.0),
     (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
]


@pytest.mark.parametrize(("att", "vel", "gyro", "force", "bias"), CASES)
def test_the_transition_matrix_is_the_strapdowns_jacobian(att, vel, gyro, force, bias):
    """Given a state moving and turning, and four IMU samples whose rate and force change,
    then every block of F matches the central-difference Jacobian of the strapdown over
    them within 5 % of the block's size, a diagonal block's part beyond the identity judged
    alone (the rest is F's first-order form over 10 ms)."""
    est = Estimator()
    g = est._g
    x0 = (1.0, 2.0, 3.0, *vel, *q_exp(att), *bias)
    samples = [(tuple(c * (1.0 + 0.1 * k) for c in gyro),
                tuple(c + 0.3 * k for c in force)) for k in range(4)]
    x1 = _propagate(x0, samples, g)
    est._c_x, est._c_t, est._h_x, est._h_t = x0, 0, x1, round(4 * DT * 1e6)
    est._c_dt2 = 4 * DT * DT
    est._P = np.eye(15)
    est._cov_step()
    F = est._F.copy()
    J = np.empty((15, 15))
    for k in range(15):
        hi = _propagate(_perturb(x0, k, EPS), samples, g)
        lo = _propagate(_perturb(x0, k, -EPS), samples, g)
        J[:, k] = (_error(hi, x1) - _error(lo, x1)) / (2 * EPS)
    for name, (r, c) in BLOCKS.items():
        fd, f = J[r:r + 3, c:c + 3], F[r:r + 3, c:c + 3]
        if r == c:  # judged on what they add to the identity (dtheta/dtheta: -[dtheta]x)
            fd, f = fd - np.eye(3), f - np.eye(3)
        scale = max(np.abs(fd).max(), 1e-9)
        assert np.abs(f - fd).max() <= 0.05 * scale + 1e-9, (name, f, fd)
    # what F leaves out is small: nothing beyond its blocks (and dp/db_g, third order)
    known = np.zeros((15, 15), dtype=bool)
    for r, c in BLOCKS.values():
        known[r:r + 3, c:c + 3] = True
    known[0:3, 9:12] = True
    assert np.abs(J[~known]).max() < 1e-9
    assert np.abs(F[~known]).max() == 0.0
