"""PID feedback-linearisation tracker on unit dual quaternions (eq. 16) and the PD
baseline (eq. 33), with the physically exact inverse dynamics of docs/model.md#dynamics.

Frames: world ENU, body FLU. The state and the reference are plain tuples; the only state the
tracker keeps is the integral of ln q_hat_e, which `reset()` clears. The law is one compiled
kernel (`tracker_kernel`, numba) on flat float arrays, which the flight core's fused step
calls too; `DualQuaternionTracker.update` is its typed Python face.
"""

from __future__ import annotations

import numpy as np

from common.config.gains import Gains
from common.config.vehicle import VehicleConfig
from common.jit import njit
from fcu.control.dualquat import (
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
    right_jacobian_inv,
)
from fcu.control.layouts import (
    DUAL_VEC_SIZE,
    K_D,
    K_G,
    K_I,
    K_IS_PD,
    K_J,
    K_LOG_RATE,
    K_MASS,
    K_P,
    K_SIZE,
    R_A,
    R_P,
    R_Q,
    R_V,
    R_W,
    R_WD,
    REFERENCE,
    T_FORCE,
    T_LOG,
    T_SIZE,
    T_TORQUE,
    T_XI,
    TRACKER_OUT,
    TRACKER_PARAMS,
    VEHICLE_STATE,
    X_P,
    X_Q,
    X_V,
    X_W,
)
from fcu.stages import Reference, TrackerOutput, VehicleState

# The kernels' arrays hold these tuples' fields in order (state_array, ref_array,
# tracker_output).
assert VEHICLE_STATE.names() == VehicleState._fields
assert REFERENCE.names() == Reference._fields
assert TRACKER_OUT.names()[:len(TrackerOutput._fields)] == TrackerOutput._fields


@njit
def reference_twist(ref: tuple[Vec3, Quat, Vec3, Vec3, Vec3, Vec3]
                    ) -> tuple[DualVec, DualVec]:
    """xi_d = omega_d + eps R_d^T p_d' and its derivative (docs/model.md#dynamics), for a
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
    wx, wy, wz = xi_e[0], xi_e[1], xi_e[2]
    r = right_jacobian_inv((2.0 * log_e[0], 2.0 * log_e[1], 2.0 * log_e[2]), (wx, wy, wz))
    ex, ey, ez = 2.0 * log_e[3], 2.0 * log_e[4], 2.0 * log_e[5]
    cx, cy, cz = wy * ez - wz * ey, wz * ex - wx * ez, wx * ey - wy * ex
    return (r[0], r[1], r[2], xi_e[3] - cx, xi_e[4] - cy, xi_e[5] - cz)


@njit
def desired_accel(j: int, ff: DualVec, cr: DualVec, k: np.ndarray, log_e: DualVec,
                  integral: np.ndarray, rate: DualVec) -> float:
    """Component j of the desired twist rate of eq. (16): xi_d' feed-forward (Ad of the
    reference's, plus the cross term) minus the PID terms
    2 k_p . ln q_hat_e + 2 k_i . int ln q_hat_e + D (D = k_d . rate)."""
    kp, ki, kd = float(k[K_P + j]), float(k[K_I + j]), float(k[K_D + j])
    return ff[j] + cr[j] - 2.0 * kp * log_e[j] - 2.0 * ki * float(integral[j]) - kd * rate[j]


@njit
def tracker_kernel(x: np.ndarray, r: np.ndarray, k: np.ndarray, integral: np.ndarray,
                   dt_s: float, out: np.ndarray) -> None:
    """Eq. (16) (or eq. 33) with the exact inverse dynamics (docs/model.md#dynamics), on flat
    arrays (fcu.control.layouts): state `x` (VEHICLE_STATE), reference `r` (REFERENCE),
    parameters `k` (TRACKER_PARAMS); the integral of ln q_hat_e (6) advances in place unless
    PD; `out` gets TRACKER_OUT."""
    p = (x[X_P], x[X_P + 1], x[X_P + 2])
    q = (x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3])
    v = (x[X_V], x[X_V + 1], x[X_V + 2])
    w = (x[X_W], x[X_W + 1], x[X_W + 2])
    ref = ((r[R_P], r[R_P + 1], r[R_P + 2]), (r[R_Q], r[R_Q + 1], r[R_Q + 2], r[R_Q + 3]),
           (r[R_V], r[R_V + 1], r[R_V + 2]), (r[R_A], r[R_A + 1], r[R_A + 2]),
           (r[R_W], r[R_W + 1], r[R_W + 2]), (r[R_WD], r[R_WD + 1], r[R_WD + 2]))
    qh = dq_from_pose(q, p)
    qh_d = dq_from_pose(ref[1], ref[0])
    qh_e = dq_mul(dq_conj(qh_d), qh)  # eq. (9)
    qh_e_conj = dq_conj(qh_e)

    xi_d, xi_d_dot = reference_twist(ref)
    ad_xi_d = dq_ad(qh_e_conj, xi_d)
    xi_e = (w[0] - ad_xi_d[0], w[1] - ad_xi_d[1], w[2] - ad_xi_d[2],
            v[0] - ad_xi_d[3], v[1] - ad_xi_d[4], v[2] - ad_xi_d[5])  # eq. (11)
    log_e = dq_log(qh_e)

    if k[K_LOG_RATE] != 0.0:
        rate = log_rate(log_e, xi_e)  # D = 2 k_d . (ln q_hat_e)'
    else:
        rate = xi_e  # D = k_d . xi_e
    ff = dq_ad(qh_e_conj, xi_d_dot)
    cr = dual_cross(ad_xi_d, xi_e)

    if k[K_IS_PD] == 0.0:  # PID: the integral of ln q_hat_e
        for j in range(DUAL_VEC_SIZE):
            integral[j] = integral[j] + log_e[j] * dt_s
    des = (desired_accel(0, ff, cr, k, log_e, integral, rate),
           desired_accel(1, ff, cr, k, log_e, integral, rate),
           desired_accel(2, ff, cr, k, log_e, integral, rate),
           desired_accel(3, ff, cr, k, log_e, integral, rate),
           desired_accel(4, ff, cr, k, log_e, integral, rate),
           desired_accel(5, ff, cr, k, log_e, integral, rate))

    # Exact inverse of xi' = J^-1(tau - w x Jw) + eps(f/m + R^T g_W - w x v).
    m, jx, jy, jz = k[K_MASS], k[K_J], k[K_J + 1], k[K_J + 2]
    jwx, jwy, jwz = jx * w[0], jy * w[1], jz * w[2]
    out[T_TORQUE] = jx * des[0] + w[1] * jwz - w[2] * jwy
    out[T_TORQUE + 1] = jy * des[1] + w[2] * jwx - w[0] * jwz
    out[T_TORQUE + 2] = jz * des[2] + w[0] * jwy - w[1] * jwx
    up_b = q_rotate_inv(q, (0.0, 0.0, 1.0))
    mg = m * k[K_G]
    out[T_FORCE] = m * (des[3] + w[1] * v[2] - w[2] * v[1]) + mg * up_b[0]
    out[T_FORCE + 1] = m * (des[4] + w[2] * v[0] - w[0] * v[2]) + mg * up_b[1]
    out[T_FORCE + 2] = m * (des[5] + w[0] * v[1] - w[1] * v[0]) + mg * up_b[2]
    for j in range(DUAL_VEC_SIZE):
        out[T_LOG + j] = log_e[j]
        out[T_XI + j] = xi_e[j]


def state_array(state: VehicleState) -> np.ndarray:
    """A VehicleState as the kernels' flat array (VEHICLE_STATE, its fields in order)."""
    return np.array((*state.p_enu_m, *state.q_enu_flu, *state.v_flu_m_s,
                     *state.omega_flu_rad_s), dtype=np.float64)


def ref_array(ref: Reference) -> np.ndarray:
    """A Reference as the kernels' flat array (REFERENCE, its fields in order)."""
    return np.array((*ref.p_enu_m, *ref.q_enu_flu, *ref.v_enu_m_s, *ref.a_enu_m_s2,
                     *ref.omega_flu_rad_s, *ref.omega_dot_flu_rad_s2), dtype=np.float64)


def tracker_output(out: list[float]) -> TrackerOutput:
    """TrackerOutput of the kernel's TRACKER_OUT values (as Python floats)."""
    f, t, e, x = T_FORCE, T_TORQUE, T_LOG, T_XI
    return TrackerOutput((out[f], out[f + 1], out[f + 2]), (out[t], out[t + 1], out[t + 2]),
                         (out[e], out[e + 1], out[e + 2], out[e + 3], out[e + 4], out[e + 5]),
                         (out[x], out[x + 1], out[x + 2], out[x + 3], out[x + 4], out[x + 5]))


class DualQuaternionTracker:
    """Eq. (16) (PID, gains with k_i) or eq. (33) (PD, k_i = 0, twist damping)."""

    def __init__(self, vehicle: VehicleConfig, gains: Gains) -> None:
        self.mass = vehicle.mass_kg
        self.inertia = vehicle.inertia_diag_kg_m2
        self.gravity = vehicle.gravity_m_s2
        self.params = np.zeros(K_SIZE)
        self.params[K_MASS] = self.mass
        TRACKER_PARAMS.view(self.params, "inertia_diag_kg_m2")[:] = self.inertia
        self.params[K_G] = self.gravity
        self.integral_array = np.zeros(DUAL_VEC_SIZE)  # the kernel's integral of ln q_hat_e
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
        TRACKER_PARAMS.view(k, "kp")[:] = (*gains.kp_r, *gains.kp_d)
        TRACKER_PARAMS.view(k, "ki")[:] = (*gains.ki_r, *gains.ki_d)
        TRACKER_PARAMS.view(k, "kd")[:] = (*gains.kd_r, *gains.kd_d)
        k[K_IS_PD] = 1.0 if gains.is_pd else 0.0
        k[K_LOG_RATE] = 1.0 if gains.damping == "log_rate" else 0.0

    def bind(self, params: np.ndarray, integral: np.ndarray) -> None:
        """Keep parameters and integral in these arrays from now on (views of a fused
        step's buffers), with their current values."""
        params[:] = self.params
        integral[:] = self.integral_array
        self.params, self.integral_array = params, integral

    def update(self, state: VehicleState, ref: Reference, dt_s: float) -> TrackerOutput:
        """One control step: desired wrench in FLU for the state, the reference and dt."""
        out = np.empty(T_SIZE)
        tracker_kernel(state_array(state), ref_array(ref), self.params, self.integral_array,
                       float(dt_s), out)
        return tracker_output(out.tolist())
