"""The estimator's flat buffers (`common.layouts.Layout`): EF_ floats and EI_ integers, as
the kernels of `fcu.estimator.filter` read them.
"""

from __future__ import annotations

from common.layouts import Layout

# ------------------------------------------------------------------ the estimator (fcu.estimator)

EKF_STATE_SIZE = 16  # nominal state (p, v, q, b_g, b_a), fcu.estimator.strapdown
EKF_ERROR_SIZE = 15  # error state (dp, dv, dtheta, db_g, db_a)

# States at the horizon (h_x), the output (o_x), the last covariance step (c_x) and before
# the fusion under way (xb); c_dt2: sum of dt^2 since that step; last_w: the newest gyro
# sample; pose: the pose under way (p, q, its variances as sent); innov: its position and
# attitude innovations, then r_p, r_a (the variances used) and the two test ratios. The
# settings the kernels read follow (squared where the filter compares or scales squares).
EKF_FLOAT = Layout(
    ("h_x", EKF_STATE_SIZE), ("o_x", EKF_STATE_SIZE), ("c_x", EKF_STATE_SIZE),
    ("xb", EKF_STATE_SIZE), ("c_dt2", 1), ("last_w", 3), ("pose", 9), ("innov", 6),
    ("r", 2), ("ratio", 2), ("gravity", 1), ("gate2", 1), ("r_pos_floor", 1),
    ("r_att_floor", 1), ("acc_noise2", 1), ("gyro_noise2", 1), ("gyro_bias_noise2", 1),
    ("acc_bias_noise2", 1), ("var_max", 1), ("var_min", EKF_ERROR_SIZE),
    ("healthy_var", 3), ("converged_var", 3), ("sd", EKF_ERROR_SIZE))
EF_H_X, EF_O_X = EKF_FLOAT.at("h_x"), EKF_FLOAT.at("o_x")
EF_C_X, EF_XB = EKF_FLOAT.at("c_x"), EKF_FLOAT.at("xb")
EF_C_DT2, EF_LAST_W = EKF_FLOAT.at("c_dt2"), EKF_FLOAT.at("last_w")
EF_POSE, EF_INNOV = EKF_FLOAT.at("pose"), EKF_FLOAT.at("innov")
EF_R, EF_RATIO = EKF_FLOAT.at("r"), EKF_FLOAT.at("ratio")
EF_G, EF_GATE2 = EKF_FLOAT.at("gravity"), EKF_FLOAT.at("gate2")
EF_R_POS_FLOOR, EF_R_ATT_FLOOR = EKF_FLOAT.at("r_pos_floor"), EKF_FLOAT.at("r_att_floor")
EF_ACC_N2, EF_GYRO_N2 = EKF_FLOAT.at("acc_noise2"), EKF_FLOAT.at("gyro_noise2")
EF_GYRO_B2, EF_ACC_B2 = EKF_FLOAT.at("gyro_bias_noise2"), EKF_FLOAT.at("acc_bias_noise2")
EF_VAR_MAX, EF_VAR_MIN = EKF_FLOAT.at("var_max"), EKF_FLOAT.at("var_min")
EF_HEALTHY_VAR, EF_CONVERGED_VAR = EKF_FLOAT.at("healthy_var"), EKF_FLOAT.at("converged_var")
EF_SD = EKF_FLOAT.at("sd")
EF_SIZE = EKF_FLOAT.size

# Times in us (-1: none yet), counters, the ring of buffered IMU samples (head, count), the
# pose queue's length, fusing (poses are being fused at the horizon), the pose under way's
# capture time; then the settings (in us, or flags).
EKF_INT = Layout(
    ("h_t", 1), ("o_t", 1), ("c_t", 1), ("resync_t", 1), ("dt_us", 1), ("n_pred", 1),
    ("last_capture_us", 1), ("last_pos_fuse_us", 1), ("last_att_fuse_us", 1),
    ("last_fusion_us", 1), ("fused", 1), ("rejected", 1), ("rejected_in_row", 1),
    ("pose_ignored", 1), ("resets", 1), ("pend_head", 1), ("pend_n", 1), ("poses_n", 1),
    ("fusing", 1), ("pose_c", 1), ("delay_us", 1), ("cov_us", 1), ("resync_us", 1),
    ("timeout_us", 1), ("queue_max", 1), ("repropagate", 1))
EI_H_T, EI_O_T, EI_C_T = EKF_INT.at("h_t"), EKF_INT.at("o_t"), EKF_INT.at("c_t")
EI_RESYNC_T, EI_DT_US = EKF_INT.at("resync_t"), EKF_INT.at("dt_us")
EI_N_PRED, EI_LAST_CAPTURE = EKF_INT.at("n_pred"), EKF_INT.at("last_capture_us")
EI_LAST_POS_FUSE, EI_LAST_ATT_FUSE = (EKF_INT.at("last_pos_fuse_us"),
                                      EKF_INT.at("last_att_fuse_us"))
EI_LAST_FUSION, EI_FUSED = EKF_INT.at("last_fusion_us"), EKF_INT.at("fused")
EI_REJECTED, EI_REJ_ROW = EKF_INT.at("rejected"), EKF_INT.at("rejected_in_row")
EI_POSE_IGNORED, EI_RESETS = EKF_INT.at("pose_ignored"), EKF_INT.at("resets")
EI_PEND_HEAD, EI_PEND_N = EKF_INT.at("pend_head"), EKF_INT.at("pend_n")
EI_POSES_N, EI_FUSING = EKF_INT.at("poses_n"), EKF_INT.at("fusing")
EI_POSE_C, EI_DELAY_US = EKF_INT.at("pose_c"), EKF_INT.at("delay_us")
EI_COV_US, EI_RESYNC_US = EKF_INT.at("cov_us"), EKF_INT.at("resync_us")
EI_TIMEOUT_US, EI_QUEUE_MAX = EKF_INT.at("timeout_us"), EKF_INT.at("queue_max")
EI_REPROPAGATE = EKF_INT.at("repropagate")
EI_SIZE = EKF_INT.size
