"""PID feedback-linearisation tracker on unit dual quaternions (eq. 16) and the PD
baseline (eq. 33), with the physically exact inverse dynamics of MODEL.md section 4.

Frames: world ENU, body FLU. The state and the reference are plain tuples; the only state the
tracker keeps is the integral of ln q_hat_e, which `reset()` clears. The law is one compiled
kernel (`tracker_kernel`, numba) on flat float arrays, which the flight core's fused step
calls too; `DualQuaternionTracker.update` is its typed Python face.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.config import Gains, VehicleConfig
from common.jit import njit
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

# Layouts of the kernel's flat arrays.
STATE_SIZE = 13  # p_enu (3), q_enu_flu (4), v_flu (3), omega_flu (3): VehicleState
REF_SIZE = 19  # p_enu, q_enu_flu, v_enu, a_enu, omega_flu, omega_dot_flu: Reference
PARAMS_SIZE = 25  # kp (6), ki (6), kd (6) per dual part; m, J (3), g, is_pd, log_rate
OUT_SIZE = 24  # force_flu (3), torque_flu (3), ln q_hat_e (6), xi_e (6)


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


@njit
def reference_twist(ref: tuple[Vec3, Quat, Vec3, Vec3, Vec3, Vec3]
                    ) -> tuple[DualVec, DualVec]:
    """xi_d = omega_d + eps R_d^T p_d' and its derivative (MODEL.md section 4), for a
    Reference (or the tuple of its fields)."""
    q = ref[1]
    w = ref[4]
    v_b = q_rotate_inv(q, ref[2])
    a_b = q_rotate_inv(q, ref[3])
    wxv = cross(w, v_b)
    wd = ref[5]
    return ((w[0], w[1], w[2], v_b[0], v_b[1], v_b[2]),
            (wd[0], wd[1], wd[2], a_b[0] - wxv[0], a_b[1] - wxv[1], a_b[2] - wxv[2]))


@njit
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


@njit
def tracker_kernel(x: np.ndarray, r: np.ndarray, k: np.ndarray, integral: np.ndarray,
                   dt_s: float, out: np.ndarray) -> None:
    """Eq. (16) (or eq. 33) with the exact inverse dynamics of MODEL.md 4, on flat arrays:
    state `x` (STATE_SIZE), reference `r` (REF_SIZE), parameters `k` (PARAMS_SIZE); the
    integral of ln q_hat_e (6) advances in place unless PD; `out` gets OUT_SIZE values."""
    p = (x[0], x[1], x[2])
    q = (x[3], x[4], x[5], x[6])
    v = (x[7], x[8], x[9])
    w = (x[10], x[11], x[12])
    ref = ((r[0], r[1], r[2]), (r[3], r[4], r[5], r[6]), (r[7], r[8], r[9]),
           (r[10], r[11], r[12]), (r[13], r[14], r[15]), (r[16], r[17], r[18]))
    qh = dq_from_pose(q, p)
    qh_d = dq_from_pose(ref[1], ref[0])
    qh_e = dq_mul(dq_conj(qh_d), qh)  # eq. (9)
    qh_e_conj = dq_conj(qh_e)

    xi_d, xi_d_dot = reference_twist(ref)
    ad_xi_d = dq_ad(qh_e_conj, xi_d)
    xi_e = (w[0] - ad_xi_d[0], w[1] - ad_xi_d[1], w[2] - ad_xi_d[2],
            v[0] - ad_xi_d[3], v[1] - ad_xi_d[4], v[2] - ad_xi_d[5])  # eq. (11)
    log_e = dq_log(qh_e)

    if k[24] != 0.0:
        rate = log_rate(log_e, xi_e)  # D = 2 k_d . (ln q_hat_e)'
    else:
        rate = xi_e  # D = k_d . xi_e
    ff = dq_ad(qh_e_conj, xi_d_dot)
    cr = dual_cross(ad_xi_d, xi_e)

    if k[23] == 0.0:  # PID: the integral of ln q_hat_e
        for j in range(6):
            integral[j] = integral[j] + log_e[j] * dt_s
    des0 = ff[0] + cr[0] - 2.0 * k[0] * log_e[0] - 2.0 * k[6] * integral[0] - k[12] * rate[0]
    des1 = ff[1] + cr[1] - 2.0 * k[1] * log_e[1] - 2.0 * k[7] * integral[1] - k[13] * rate[1]
    des2 = ff[2] + cr[2] - 2.0 * k[2] * log_e[2] - 2.0 * k[8] * integral[2] - k[14] * rate[2]
    des3 = ff[3] + cr[3] - 2.0 * k[3] * log_e[3] - 2.0 * k[9] * integral[3] - k[15] * rate[3]
    des4 = ff[4] + cr[4] - 2.0 * k[4] * log_e[4] - 2.0 * k[10] * integral[4] - k[16] * rate[4]
    des5 = ff[5] + cr[5] - 2.0 * k[5] * log_e[5] - 2.0 * k[11] * integral[5] - k[17] * rate[5]

    # Exact inverse of xi' = J^-1(tau - w x Jw) + eps(f/m + R^T g_W - w x v).
    m, jx, jy, jz = k[18], k[19], k[20], k[21]
    jwx, jwy, jwz = jx * w[0], jy * w[1], jz * w[2]
    out[3] = jx * des0 + w[1] * jwz - w[2] * jwy
    out[4] = jy * des1 + w[2] * jwx - w[0] * jwz
    out[5] = jz * des2 + w[0] * jwy - w[1] * jwx
    up_b = q_rotate_inv(q, (0.0, 0.0, 1.0))
    mg = m * k[22]
    out[0] = m * (des3 + w[1] * v[2] - w[2] * v[1]) + mg * up_b[0]
    out[1] = m * (des4 + w[2] * v[0] - w[0] * v[2]) + mg * up_b[1]
    out[2] = m * (des5 + w[0] * v[1] - w[1] * v[0]) + mg * up_b[2]
    for j in range(6):
        out[6 + j] = log_e[j]
        out[12 + j] = xi_e[j]


def state_array(state: VehicleState) -> np.ndarray:
    """A VehicleState as the kernels' flat array (STATE_SIZE)."""
    return np.array((*state.p_enu_m, *state.q_enu_flu, *state.v_flu_m_s,
                     *state.omega_flu_rad_s), dtype=np.float64)


def ref_array(ref: Reference) -> np.ndarray:
    """A Reference as the kernels' flat array (REF_SIZE)."""
    return np.array((*ref.p_enu_m, *ref.q_enu_flu, *ref.v_enu_m_s, *ref.a_enu_m_s2,
                     *ref.omega_flu_rad_s, *ref.omega_dot_flu_rad_s2), dtype=np.float64)


def tracker_output(out: list[float]) -> TrackerOutput:
    """TrackerOutput of the kernel's OUT_SIZE values (as Python floats)."""
    return TrackerOutput((out[0], out[1], out[2]), (out[3], out[4], out[5]),
                         (out[6], out[7], out[8], out[9], out[10], out[11]),
                         (out[12], out[13], out[14], out[15], out[16], out[17]))


class DualQuaternionTracker:
    """Eq. (16) (PID, gains with k_i) or eq. (33) (PD, k_i = 0, twist damping)."""

    def __init__(self, vehicle: VehicleConfig, gains: Gains) -> None:
        self.mass = vehicle.mass_kg
        self.inertia = vehicle.inertia_diag_kg_m2
        self.gravity = vehicle.gravity_m_s2
        self.params = np.zeros(PARAMS_SIZE)
        self.params[18:23] = (self.mass, *self.inertia, self.gravity)
        self.integral_array = np.zeros(6)  # the kernel's integral of ln q_hat_e
        self.set_gains(gains)

    @property
    def integral(self) -> DualVec:
        i = self.integral_array.tolist()
        return (i[0], i[1], i[2], i[3], i[4], i[5])

    @integral.setter
    def integral(self, value: DualVec) -> None:
        self.integral_array[:] = value

    def reset(self) -> None:
        self.integral_array[:] = 0.0

    def set_gains(self, gains: Gains) -> None:
        self.gains = gains
        k = self.params
        k[0:18] = (*gains.kp_r, *gains.kp_d, *gains.ki_r, *gains.ki_d, *gains.kd_r,
                   *gains.kd_d)
        k[23] = 1.0 if gains.is_pd else 0.0
        k[24] = 1.0 if gains.damping == "log_rate" else 0.0

    def bind(self, params: np.ndarray, integral: np.ndarray) -> None:
        """Keep parameters and integral in these arrays from now on (views of a fused
        step's buffers), with their current values."""
        params[:] = self.params
        integral[:] = self.integral_array
        self.params, self.integral_array = params, integral

    def update(self, state: VehicleState, ref: Reference, dt_s: float) -> TrackerOutput:
        """One control step: desired wrench in FLU for the state, the reference and dt."""
        out = np.empty(OUT_SIZE)
        tracker_kernel(state_array(state), ref_array(ref), self.params, self.integral_array,
                       float(dt_s), out)
        return tracker_output(out.tolist())
