"""Named layouts of the compiled kernels' flat float arrays, one table per array.

Each array is a `Layout`: its fields in order, as (name, size). The integer offsets the
kernels index with are module constants taken from those tables (numba freezes a module's
globals when it compiles a kernel, so `x[X_Q + 1]` costs what `x[4]` does); the Python code
that packs and unpacks the arrays uses the same constants. Frames and units are those of the
field names (world ENU, body FLU, SI).

Prefixes: X_ vehicle state, R_ reference, K_ tracker parameters, T_ tracker output
(fcu.control.tracker); A_ allocator parameters, AO_ allocation output, L_ lag compensator
parameters, LS_ its state (fcu.control.allocation); CI_ CP_ CS_ CO_ the fused control step's input,
parameters, state and output (fcu.control.core); PP_ plant parameters, PR_ one rotor's block in
them, PS_ plant state (a truth-log row), PC_ actuator command (sitl.plant); D_ a disturbance term
(sitl.disturbance);
EF_ EI_ the estimator's float and integer buffers (fcu.estimator.filter).
"""

from __future__ import annotations

from common.vehicle_constants import N_ROTORS

DUAL_VEC_SIZE = 6  # a dual vector: real xyz, dual xyz


class Layout:
    """The fields of a flat array in order: `at(name)` is a field's offset, `size` the
    array's length."""

    def __init__(self, *fields: tuple[str, int]) -> None:
        self.fields = fields
        self._offsets: dict[str, int] = {}
        offset = 0
        for name, size in fields:
            self._offsets[name] = offset
            offset += size
        self.size = offset

    def at(self, name: str) -> int:
        """The offset of field `name`."""
        return self._offsets[name]

    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.fields)


# ------------------------------------------------------------------ the tracker (eq. 16)

VEHICLE_STATE = Layout(("p_enu_m", 3), ("q_enu_flu", 4), ("v_flu_m_s", 3),
                       ("omega_flu_rad_s", 3))
X_P, X_Q = VEHICLE_STATE.at("p_enu_m"), VEHICLE_STATE.at("q_enu_flu")
X_V, X_W = VEHICLE_STATE.at("v_flu_m_s"), VEHICLE_STATE.at("omega_flu_rad_s")
X_SIZE = VEHICLE_STATE.size

REFERENCE = Layout(("p_enu_m", 3), ("q_enu_flu", 4), ("v_enu_m_s", 3), ("a_enu_m_s2", 3),
                   ("omega_flu_rad_s", 3), ("omega_dot_flu_rad_s2", 3))
R_P, R_Q = REFERENCE.at("p_enu_m"), REFERENCE.at("q_enu_flu")
R_V, R_A = REFERENCE.at("v_enu_m_s"), REFERENCE.at("a_enu_m_s2")
R_W, R_WD = REFERENCE.at("omega_flu_rad_s"), REFERENCE.at("omega_dot_flu_rad_s2")
R_SIZE = REFERENCE.size

# Gains per dual part (real xyz, dual xyz, eq. 3); is_pd: eq. (33) without the integral;
# log_rate: D = 2 k_d . (ln q_hat_e)' (else k_d . xi_e).
TRACKER_PARAMS = Layout(("kp", DUAL_VEC_SIZE), ("ki", DUAL_VEC_SIZE), ("kd", DUAL_VEC_SIZE),
                        ("mass_kg", 1), ("inertia_diag_kg_m2", 3), ("gravity_m_s2", 1),
                        ("is_pd", 1), ("log_rate", 1))
K_P, K_I, K_D = TRACKER_PARAMS.at("kp"), TRACKER_PARAMS.at("ki"), TRACKER_PARAMS.at("kd")
K_MASS, K_J = TRACKER_PARAMS.at("mass_kg"), TRACKER_PARAMS.at("inertia_diag_kg_m2")
K_G = TRACKER_PARAMS.at("gravity_m_s2")
K_IS_PD, K_LOG_RATE = TRACKER_PARAMS.at("is_pd"), TRACKER_PARAMS.at("log_rate")
K_SIZE = TRACKER_PARAMS.size

# ln q_hat_e = 1/2 (theta_e n_e + eps p_e) and xi_e (eq. 11); `reserved` is not written
# (the fused step's output keeps the allocation at the offset it always had).
TRACKER_OUT = Layout(("force_flu_n", 3), ("torque_flu_nm", 3), ("log_error", DUAL_VEC_SIZE),
                     ("twist_error", DUAL_VEC_SIZE), ("reserved", 6))
T_FORCE, T_TORQUE = TRACKER_OUT.at("force_flu_n"), TRACKER_OUT.at("torque_flu_nm")
T_LOG, T_XI = TRACKER_OUT.at("log_error"), TRACKER_OUT.at("twist_error")
T_SIZE = TRACKER_OUT.size
assert T_TORQUE == T_FORCE + 3, "the wrench [f; tau] is one slice"
T_WRENCH_END = T_TORQUE + 3

# ------------------------------------------------------------------ the allocation (eqs. 27-29)

PINV_SIZE = 2 * N_ROTORS * 6  # A^+ row-major: 2 n rows (Omega) of the 6 wrench components

ALLOC_PARAMS = Layout(("pinv", PINV_SIZE), ("w_max_rad_s", 1), ("hold_speed_rad_s", 1))
A_PINV, A_WMAX = ALLOC_PARAMS.at("pinv"), ALLOC_PARAMS.at("w_max_rad_s")
A_HOLD = ALLOC_PARAMS.at("hold_speed_rad_s")
A_SIZE = ALLOC_PARAMS.size

ALLOC_OUT = Layout(("omega_sq", 2 * N_ROTORS), ("speed_rad_s", N_ROTORS),
                   ("tilt_raw_rad", N_ROTORS), ("tilt_rad", N_ROTORS), ("saturated", 1))
AO_OMEGA, AO_SPEED = ALLOC_OUT.at("omega_sq"), ALLOC_OUT.at("speed_rad_s")
AO_TILT_RAW, AO_TILT = ALLOC_OUT.at("tilt_raw_rad"), ALLOC_OUT.at("tilt_rad")
AO_SATURATED = ALLOC_OUT.at("saturated")
AO_SIZE = ALLOC_OUT.size

# The lag compensator's A^+ comes first too: `solve_kernel` reads either parameter array.
LAG_PARAMS = Layout(("pinv", PINV_SIZE), ("w_max_rad_s", 1), ("lead_max_rad_s", 1),
                    ("hold_speed_rad_s", 1), ("tau_up_s", 1), ("tau_down_s", 1),
                    ("tilt_rate_max_rad_s", 1))
L_PINV, L_WMAX = LAG_PARAMS.at("pinv"), LAG_PARAMS.at("w_max_rad_s")
L_LEAD_MAX, L_HOLD = LAG_PARAMS.at("lead_max_rad_s"), LAG_PARAMS.at("hold_speed_rad_s")
L_TAU_UP, L_TAU_DOWN = LAG_PARAMS.at("tau_up_s"), LAG_PARAMS.at("tau_down_s")
L_TILT_RATE = LAG_PARAMS.at("tilt_rate_max_rad_s")
L_SIZE = LAG_PARAMS.size
assert A_PINV == L_PINV, "solve_kernel reads A^+ at the same offset in both"

# Last nominal speeds and tilts (has_last: they are set), the rotor model (has_model), the
# mean correction b_i.
LAG_STATE = Layout(("w_last_rad_s", N_ROTORS), ("a_last_rad", N_ROTORS), ("has_last", 1),
                   ("model_rad_s", N_ROTORS), ("has_model", 1), ("bias_rad_s", N_ROTORS))
LS_W_LAST, LS_A_LAST = LAG_STATE.at("w_last_rad_s"), LAG_STATE.at("a_last_rad")
LS_HAS_LAST, LS_MODEL = LAG_STATE.at("has_last"), LAG_STATE.at("model_rad_s")
LS_HAS_MODEL, LS_BIAS = LAG_STATE.at("has_model"), LAG_STATE.at("bias_rad_s")
LS_SIZE = LAG_STATE.size

# ------------------------------------------------------------------ the fused control step

CORE_IN = Layout(("state", X_SIZE), ("reference", R_SIZE), ("dt_s", 1), ("lag_on", 1))
CI_X, CI_R = CORE_IN.at("state"), CORE_IN.at("reference")
CI_DT, CI_LAG_ON = CORE_IN.at("dt_s"), CORE_IN.at("lag_on")
CI_SIZE = CORE_IN.size

CORE_PARAMS = Layout(("tracker", K_SIZE), ("allocator", A_SIZE), ("compensator", L_SIZE))
CP_TRACKER, CP_ALLOC = CORE_PARAMS.at("tracker"), CORE_PARAMS.at("allocator")
CP_LAG = CORE_PARAMS.at("compensator")
CP_SIZE = CORE_PARAMS.size

CORE_STATE = Layout(("integral", DUAL_VEC_SIZE), ("tilt_rad", N_ROTORS),
                    ("compensator", LS_SIZE))
CS_INTEGRAL, CS_TILT = CORE_STATE.at("integral"), CORE_STATE.at("tilt_rad")
CS_LAG = CORE_STATE.at("compensator")
CS_SIZE = CORE_STATE.size

CORE_OUT = Layout(("tracker", T_SIZE), ("allocation", AO_SIZE))
CO_TRACKER, CO_ALLOC = CORE_OUT.at("tracker"), CORE_OUT.at("allocation")
CO_SIZE = CORE_OUT.size

# ------------------------------------------------------------------ the plant (sitl.plant)

# Force and torque per unit w^2 with the thrust along e_v and along e_l (docs/model.md#geometry).
PLANT_ROTOR = Layout(("f_v", 3), ("f_l", 3), ("tau_v", 3), ("tau_l", 3))
PR_F_V, PR_F_L = PLANT_ROTOR.at("f_v"), PLANT_ROTOR.at("f_l")
PR_TAU_V, PR_TAU_L = PLANT_ROTOR.at("tau_v"), PLANT_ROTOR.at("tau_l")
PR_SIZE = PLANT_ROTOR.size

# decay_*: e^(-h / tau) over a step h (half: over h / 2); dist_t0_s: the disturbances' clock.
PLANT_PARAMS = Layout(
    ("mass_kg", 1), ("inertia_diag_kg_m2", 3), ("gravity_m_s2", 1), ("w_max_rad_s", 1),
    ("tau_up_s", 1), ("tau_down_s", 1), ("tilt_rate_max_rad_s", 1), ("dt_us", 1),
    ("ideal", 1), ("ground", 1), ("decay_up", 1), ("decay_down", 1), ("decay_half_up", 1),
    ("decay_half_down", 1), ("dist_active", 1), ("dist_t0_s", 1),
    ("rotors", PR_SIZE * N_ROTORS))
PP_MASS, PP_J = PLANT_PARAMS.at("mass_kg"), PLANT_PARAMS.at("inertia_diag_kg_m2")
PP_G, PP_WMAX = PLANT_PARAMS.at("gravity_m_s2"), PLANT_PARAMS.at("w_max_rad_s")
PP_TAU_UP, PP_TAU_DOWN = PLANT_PARAMS.at("tau_up_s"), PLANT_PARAMS.at("tau_down_s")
PP_TILT_RATE, PP_DT_US = PLANT_PARAMS.at("tilt_rate_max_rad_s"), PLANT_PARAMS.at("dt_us")
PP_IDEAL, PP_GROUND = PLANT_PARAMS.at("ideal"), PLANT_PARAMS.at("ground")
PP_DECAY_UP, PP_DECAY_DOWN = PLANT_PARAMS.at("decay_up"), PLANT_PARAMS.at("decay_down")
PP_DECAY_HALF_UP = PLANT_PARAMS.at("decay_half_up")
PP_DECAY_HALF_DOWN = PLANT_PARAMS.at("decay_half_down")
PP_DIST_ACTIVE, PP_DIST_T0 = PLANT_PARAMS.at("dist_active"), PLANT_PARAMS.at("dist_t0_s")
PP_ROTORS = PLANT_PARAMS.at("rotors")
PP_SIZE = PLANT_PARAMS.size

# A truth-log row (sitl.plant.TRUTH_COLUMNS).
PLANT_STATE = Layout(("time_us", 1), ("p_enu_m", 3), ("v_enu_m_s", 3), ("q_enu_flu", 4),
                     ("omega_flu_rad_s", 3), ("rotor_speed_rad_s", N_ROTORS),
                     ("tilt_rad", N_ROTORS), ("landed", 1))
PS_TIME, PS_P = PLANT_STATE.at("time_us"), PLANT_STATE.at("p_enu_m")
PS_V, PS_Q = PLANT_STATE.at("v_enu_m_s"), PLANT_STATE.at("q_enu_flu")
PS_W, PS_SPEED = PLANT_STATE.at("omega_flu_rad_s"), PLANT_STATE.at("rotor_speed_rad_s")
PS_TILT, PS_LANDED = PLANT_STATE.at("tilt_rad"), PLANT_STATE.at("landed")
PS_SIZE = PLANT_STATE.size

PLANT_COMMAND = Layout(("rotor_speed_rad_s", N_ROTORS), ("tilt_rad", N_ROTORS))
PC_SPEED, PC_TILT = PLANT_COMMAND.at("rotor_speed_rad_s"), PLANT_COMMAND.at("tilt_rad")
PC_SIZE = PLANT_COMMAND.size

# One disturbance term: part (0 force, 1 torque), pulse (1) or sine (0), its window, the
# sine's omega and phase, the amplitude per FLU axis.
DISTURBANCE_TERM = Layout(("part", 1), ("pulse", 1), ("start_s", 1), ("end_s", 1),
                          ("omega_rad_s", 1), ("phase_rad", 1), ("amplitude", 3))
D_PART, D_PULSE = DISTURBANCE_TERM.at("part"), DISTURBANCE_TERM.at("pulse")
D_START, D_END = DISTURBANCE_TERM.at("start_s"), DISTURBANCE_TERM.at("end_s")
D_OMEGA, D_PHASE = DISTURBANCE_TERM.at("omega_rad_s"), DISTURBANCE_TERM.at("phase_rad")
D_AMPLITUDE = DISTURBANCE_TERM.at("amplitude")
D_SIZE = DISTURBANCE_TERM.size

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
