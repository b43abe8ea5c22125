"""The filter's flat buffers as `fcu.estimator.filter`'s kernels read them, for settings.

`filter_buffers` returns (fb, ib, M, pend_t, pend_v, pose_c, pose_v): the float and integer
buffers (`fcu.estimator.layouts` EF_*, EI_*: unaligned states, -1 times, the settings the kernels
read), P and F (M[0], M[1] = I), the ring of RING buffered IMU samples (it grows when full)
and the pose queue (pose_queue_max + 1 rows: a pose is inserted before the oldest is dropped).
"""

from __future__ import annotations

import numpy as np

from fcu.estimator.layouts import (
    EF_ACC_B2,
    EF_ACC_N2,
    EF_C_X,
    EF_CONVERGED_VAR,
    EF_G,
    EF_GATE2,
    EF_GYRO_B2,
    EF_GYRO_N2,
    EF_H_X,
    EF_HEALTHY_VAR,
    EF_O_X,
    EF_R_ATT_FLOOR,
    EF_R_POS_FLOOR,
    EF_SIZE,
    EF_VAR_MAX,
    EF_VAR_MIN,
    EI_C_T,
    EI_COV_US,
    EI_DELAY_US,
    EI_H_T,
    EI_LAST_ATT_FUSE,
    EI_LAST_CAPTURE,
    EI_LAST_FUSION,
    EI_LAST_POS_FUSE,
    EI_O_T,
    EI_QUEUE_MAX,
    EI_REPROPAGATE,
    EI_RESYNC_T,
    EI_RESYNC_US,
    EI_SIZE,
    EI_TIMEOUT_US,
)
from fcu.estimator.settings import EstimatorSettings
from fcu.estimator.strapdown import N, State

ZERO16: State = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                 0.0)
RING = 64  # buffered IMU samples the ring holds at first

Buffers = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                np.ndarray]


def filter_buffers(s: EstimatorSettings) -> Buffers:
    """The unaligned filter's buffers for settings s (squares as the filter computes them)."""
    fb = np.zeros(EF_SIZE)
    for i in (EF_H_X, EF_O_X, EF_C_X):
        fb[i:i + 16] = ZERO16
    fb[EF_G] = s.gravity_m_s2
    fb[EF_GATE2] = s.pose_gate_sd * s.pose_gate_sd
    fb[EF_R_POS_FLOOR] = s.pose_pos_noise_m ** 2
    fb[EF_R_ATT_FLOOR] = s.pose_att_noise_rad ** 2
    fb[EF_ACC_N2] = s.accel_noise_m_s2 ** 2
    fb[EF_GYRO_N2] = s.gyro_noise_rad_s ** 2
    fb[EF_GYRO_B2] = s.gyro_bias_noise_rad_s2 ** 2
    fb[EF_ACC_B2] = s.accel_bias_noise_m_s3 ** 2
    fb[EF_VAR_MAX] = s.var_max
    fb[EF_VAR_MIN:EF_VAR_MIN + N] = [1e-14] * 9 + [1e-16] * 6
    fb[EF_HEALTHY_VAR:EF_HEALTHY_VAR + 3] = (
        s.healthy_pos_sd_max_m ** 2, s.healthy_vel_sd_max_m_s ** 2,
        s.healthy_att_sd_max_rad ** 2)
    fb[EF_CONVERGED_VAR:EF_CONVERGED_VAR + 3] = (
        s.converged_pos_sd_m ** 2, s.converged_vel_sd_m_s ** 2, s.converged_att_sd_rad ** 2)
    ib = np.zeros(EI_SIZE, dtype=np.int64)
    for i in (EI_H_T, EI_O_T, EI_C_T, EI_RESYNC_T, EI_LAST_CAPTURE, EI_LAST_POS_FUSE,
              EI_LAST_ATT_FUSE, EI_LAST_FUSION):
        ib[i] = -1
    ib[EI_DELAY_US] = round(s.pose_delay_s * 1e6)
    ib[EI_COV_US] = round(s.cov_period_s * 1e6)
    ib[EI_RESYNC_US] = round(s.output_resync_s * 1e6)
    ib[EI_TIMEOUT_US] = round(s.pose_reset_timeout_s * 1e6)
    ib[EI_QUEUE_MAX] = s.pose_queue_max
    ib[EI_REPROPAGATE] = 1 if s.output_repropagate else 0
    M = np.zeros((2, N, N))  # P, F
    M[1] = np.eye(N)
    q = s.pose_queue_max + 1
    return (fb, ib, M, np.zeros(RING, dtype=np.int64), np.zeros((RING, 6)),
            np.zeros(q, dtype=np.int64), np.zeros((q, 9)))

