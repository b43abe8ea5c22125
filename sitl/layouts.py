"""The plant's flat arrays (`common.layouts.Layout`), one table per array.

Prefixes: PP_ plant parameters, PR_ one rotor's block in them, PS_ plant state (a truth-log
row), PC_ actuator command (sitl.plant); D_ a disturbance term (sitl.disturbance).
"""

from __future__ import annotations

from common.layouts import Layout
from common.vehicle_constants import N_ROTORS

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
