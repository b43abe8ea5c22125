"""PID feedback-linearisation tracker on unit dual quaternions (eq. 16) and the PD
baseline (eq. 33), with the physically exact inverse dynamics of MODEL.md section 4.

Frames: world ENU, body FLU. The state and the reference are plain tuples; the only state the
tracker keeps is the integral of ln q_hat_e, which `reset()` clears.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from common.config import Gains, VehicleConfig
from fcu.dualquat import (
    DualVec,
    Quat,
    Vec3,
    cross,
    dq_ad,
    dq_conj,
    dq_from_pose,
    dq_log,
    dq_mul,
    dual_cross,
    q_rotate_inv,
)


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


def reference_twist(ref: Reference) -> tuple[DualVec, DualVec]:
    """xi_d = omega_d + eps R_d^T p_d' and its derivative (MODEL.md section 4)."""
    q = ref.q_enu_flu
    w = ref.omega_flu_rad_s
    v_b = q_rotate_inv(q, ref.v_enu_m_s)
    a_b = q_rotate_inv(q, ref.a_enu_m_s2)
    wxv = cross(w, v_b)
    wd = ref.omega_dot_flu_rad_s2
    return ((w[0], w[1], w[2], v_b[0], v_b[1], v_b[2]),
            (wd[0], wd[1], wd[2], a_b[0] - wxv[0], a_b[1] - wxv[1], a_b[2] - wxv[2]))


def log_rate(log_e: DualVec, xi_e: DualVec) -> DualVec:
    """d/dt (2 ln q_hat_e) = Jr^-1(phi) omega_e + eps (v_e - omega_e x p_e).

    phi = theta n is the rotation vector of q_e (= 2 x real part of the log), p_e the error
    position in the body frame; q_hat_e' = 1/2 q_hat_e xi_e (eq. 10) gives both terms.
    """
    px, py, pz = 2.0 * log_e[0], 2.0 * log_e[1], 2.0 * log_e[2]
    wx, wy, wz = xi_e[0], xi_e[1], xi_e[2]
    th2 = px * px + py * py + pz * pz
    if th2 < 1e-8:
        c = 1.0 / 12.0 + th2 / 720.0
    else:
        th = math.sqrt(th2)
        c = 1.0 / th2 - 0.5 / (th * math.tan(0.5 * th))
    # phi x w and phi x (phi x w)
    ax, ay, az = py * wz - pz * wy, pz * wx - px * wz, px * wy - py * wx
    bx, by, bz = py * az - pz * ay, pz * ax - px * az, px * ay - py * ax
    ex, ey, ez = 2.0 * log_e[3], 2.0 * log_e[4], 2.0 * log_e[5]
    cx, cy, cz = wy * ez - wz * ey, wz * ex - wx * ez, wx * ey - wy * ex
    return (wx + 0.5 * ax + c * bx, wy + 0.5 * ay + c * by, wz + 0.5 * az + c * bz,
            xi_e[3] - cx, xi_e[4] - cy, xi_e[5] - cz)


class DualQuaternionTracker:
    """Eq. (16) (PID, gains with k_i) or eq. (33) (PD, k_i = 0, twist damping)."""

    def __init__(self, vehicle: VehicleConfig, gains: Gains) -> None:
        self.mass = vehicle.mass_kg
        self.inertia = vehicle.inertia_diag_kg_m2
        self.gravity = vehicle.gravity_m_s2
        self.gains = gains
        self.integral: DualVec = (0.0,) * 6

    def reset(self) -> None:
        self.integral = (0.0,) * 6

    def set_gains(self, gains: Gains) -> None:
        self.gains = gains

    def update(self, state: VehicleState, ref: Reference, dt_s: float) -> TrackerOutput:
        """One control step: desired wrench in FLU for the state, the reference and dt."""
        g = self.gains
        q = state.q_enu_flu
        qh = dq_from_pose(q, state.p_enu_m)
        qh_d = dq_from_pose(ref.q_enu_flu, ref.p_enu_m)
        qh_e = dq_mul(dq_conj(qh_d), qh)  # eq. (9)
        qh_e_conj = dq_conj(qh_e)

        xi_d, xi_d_dot = reference_twist(ref)
        w, v = state.omega_flu_rad_s, state.v_flu_m_s
        ad_xi_d = dq_ad(qh_e_conj, xi_d)
        xi_e = (w[0] - ad_xi_d[0], w[1] - ad_xi_d[1], w[2] - ad_xi_d[2],
                v[0] - ad_xi_d[3], v[1] - ad_xi_d[4], v[2] - ad_xi_d[5])  # eq. (11)
        log_e = dq_log(qh_e)

        if g.damping == "log_rate":
            rate = log_rate(log_e, xi_e)  # D = 2 k_d . (ln q_hat_e)'
        else:
            rate = xi_e  # D = k_d . xi_e
        ff = dq_ad(qh_e_conj, xi_d_dot)
        cr = dual_cross(ad_xi_d, xi_e)

        kpr, kpd, kir, kid, kdr, kdd = g.kp_r, g.kp_d, g.ki_r, g.ki_d, g.kd_r, g.kd_d
        i = self.integral
        if not g.is_pd:
            i = tuple(i[k] + log_e[k] * dt_s for k in range(6))  # type: ignore[assignment]
            self.integral = i
        kp = (kpr[0], kpr[1], kpr[2], kpd[0], kpd[1], kpd[2])
        ki = (kir[0], kir[1], kir[2], kid[0], kid[1], kid[2])
        kd = (kdr[0], kdr[1], kdr[2], kdd[0], kdd[1], kdd[2])
        des = [ff[k] + cr[k] - 2.0 * kp[k] * log_e[k] - 2.0 * ki[k] * i[k] - kd[k] * rate[k]
               for k in range(6)]

        # Exact inverse of xi' = J^-1(tau - w x Jw) + eps(f/m + R^T g_W - w x v).
        jx, jy, jz = self.inertia
        jwx, jwy, jwz = jx * w[0], jy * w[1], jz * w[2]
        torque = (jx * des[0] + w[1] * jwz - w[2] * jwy,
                  jy * des[1] + w[2] * jwx - w[0] * jwz,
                  jz * des[2] + w[0] * jwy - w[1] * jwx)
        up_b = q_rotate_inv(q, (0.0, 0.0, 1.0))
        m, mg = self.mass, self.mass * self.gravity
        force = (m * (des[3] + w[1] * v[2] - w[2] * v[1]) + mg * up_b[0],
                 m * (des[4] + w[2] * v[0] - w[0] * v[2]) + mg * up_b[1],
                 m * (des[5] + w[0] * v[1] - w[1] * v[0]) + mg * up_b[2])
        return TrackerOutput(force, torque, log_e, xi_e)
