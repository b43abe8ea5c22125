"""The control step's flat arrays (`common.layouts.Layout`), one table per array.

Prefixes: X_ vehicle state, R_ reference, K_ tracker parameters, T_ tracker output
(fcu.control.tracker); A_ allocator parameters, AO_ allocation output, L_ lag compensator
parameters, LS_ its state (fcu.control.allocation); CI_ CP_ CS_ CO_ the fused control step's
input, parameters, state and output (fcu.control.core).
"""

from __future__ import annotations

from common.layouts import Layout
from common.vehicle_constants import N_ROTORS

DUAL_VEC_SIZE = 6  # a dual vector: real xyz, dual xyz


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
