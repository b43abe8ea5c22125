"""The types the pipeline's stages pass each other (docs/architecture.md#the-fcus-pipeline):
the vehicle's state (the state input or the estimator's), the reference (the commander's
modes, missions and trajectories), and the tracker's wrench and errors (eqs. 11, 16). Frames
world ENU and body FLU, SI units; the kernels' flat layouts of the same fields are in
`fcu.control.layouts`.
"""

from __future__ import annotations

from typing import NamedTuple

from fcu.control.dualquat import DualVec, Quat, Vec3


class VehicleState(NamedTuple):
    """Pose and twist of the body: q_enu_flu rotates FLU vectors into ENU."""

    p_enu_m: Vec3
    q_enu_flu: Quat
    v_flu_m_s: Vec3  # linear velocity of the CoM in the body frame (dual part of xi)
    omega_flu_rad_s: Vec3


class Reference(NamedTuple):
    """Desired pose, velocity and acceleration from a trajectory or a mission item."""

    p_enu_m: Vec3
    q_enu_flu: Quat
    v_enu_m_s: Vec3
    a_enu_m_s2: Vec3
    omega_flu_rad_s: Vec3  # desired body rate, in the desired body frame
    omega_dot_flu_rad_s2: Vec3


def pose_ref(p_enu_m: Vec3, q_enu_flu: Quat) -> Reference:
    """A pose held still: zero velocity, acceleration and rates."""
    zero = (0.0, 0.0, 0.0)
    return Reference(p_enu_m, q_enu_flu, zero, zero, zero, zero)


class TrackerOutput(NamedTuple):
    force_flu_n: Vec3
    torque_flu_nm: Vec3
    log_error: DualVec  # ln q_hat_e = 1/2 (theta_e n_e + eps p_e)
    twist_error: DualVec  # xi_e (eq. 11)
