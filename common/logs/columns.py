"""The columns of the two flight logs as arrays: the plant's ground truth (`truth.ulg`, rows
of `sitl.plant.truth_row`) and the FCU's onboard log (`onboard.ulg`, rows of
`fcu.control.core.onboard_row`). Both sides write them and the ground station reads them, so
they live here, apart from either (ENU/FLU, SI units)."""

from __future__ import annotations

from common.vehicle_constants import N_ROTORS

TRUTH_COLUMNS = ("time_us", "px", "py", "pz", "vx", "vy", "vz", "qw", "qx", "qy", "qz",
                 "wx", "wy", "wz", *(f"rotor{i}" for i in range(N_ROTORS)),
                 *(f"tilt{i}" for i in range(N_ROTORS)), "landed")

ONBOARD_COLUMNS = (
    "time_us", "px", "py", "pz", "qw", "qx", "qy", "qz", "vbx", "vby", "vbz", "wx", "wy", "wz",
    "pdx", "pdy", "pdz", "qdw", "qdx", "qdy", "qdz", "vdx", "vdy", "vdz", "wdx", "wdy", "wdz",
    "fx", "fy", "fz", "tx", "ty", "tz",
    *(f"rotor_cmd{i}" for i in range(N_ROTORS)), *(f"tilt_cmd{i}" for i in range(N_ROTORS)),
    *(f"tilt_raw{i}" for i in range(N_ROTORS)), "saturated", "armed", "step_us",
    # ln q_hat_e = 1/2 (theta_e n_e + eps p_e) (eq. 16) and the twist error xi_e (eq. 11)
    "lnqe_rx", "lnqe_ry", "lnqe_rz", "lnqe_dx", "lnqe_dy", "lnqe_dz",
    "xie_rx", "xie_ry", "xie_rz", "xie_dx", "xie_dy", "xie_dz")
