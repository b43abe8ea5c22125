"""The plant's step as compiled kernels (numba) on flat arrays (sitl.layouts): the
parameters PLANT_PARAMS, the state PLANT_STATE (a truth-log row), the command PLANT_COMMAND.

The rigid body (docs/model.md#plant): p' = v, m v' = R(q) f_b + m g_W, q' = 1/2 q (0, w),
J w' = tau_b - w x J w in ENU/FLU, integrated by classical RK4. The actuators (ibid.):
a first-order rotor lag towards the command clamped to [0, w_max] and a rate-limited tilt
servo, both exact in closed form over a held command; the rotor wrench is the per-rotor sum
F_i = c_f w_i^2 n_i, Q_i = -sigma_i c_d w_i^2 n_i. `sitl.plant.Plant` is their Python face.
"""

from __future__ import annotations

import math

import numpy as np

from common.jit import njit
from common.vehicle_constants import N_ROTORS
from sitl.disturbance import disturbance_kernel
from sitl.layouts import (
    PC_SPEED,
    PC_TILT,
    PP_DECAY_DOWN,
    PP_DECAY_HALF_DOWN,
    PP_DECAY_HALF_UP,
    PP_DECAY_UP,
    PP_DIST_ACTIVE,
    PP_DIST_T0,
    PP_DT_US,
    PP_G,
    PP_GROUND,
    PP_IDEAL,
    PP_J,
    PP_MASS,
    PP_ROTORS,
    PP_TAU_DOWN,
    PP_TAU_UP,
    PP_TILT_RATE,
    PP_WMAX,
    PR_F_L,
    PR_F_V,
    PR_SIZE,
    PR_TAU_L,
    PR_TAU_V,
    PS_LANDED,
    PS_P,
    PS_Q,
    PS_SPEED,
    PS_TILT,
    PS_TIME,
    PS_V,
    PS_W,
)

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Wrench = tuple[float, float, float, float, float, float]

# A state row's velocities, zeroed on the ground.
_AT_REST = (PS_V, PS_V + 1, PS_V + 2, PS_W, PS_W + 1, PS_W + 2)


@njit
def rotate(q: Quat, v: Vec3) -> Vec3:
    """R(q) v via the rotation matrix of q (the controller uses another formula)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    vx, vy, vz = v[0], v[1], v[2]
    return ((1 - 2 * (y * y + z * z)) * vx + 2 * (x * y - w * z) * vy + 2 * (x * z + w * y) * vz,
            2 * (x * y + w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z - w * x) * vz,
            2 * (x * z - w * y) * vx + 2 * (y * z + w * x) * vy + (1 - 2 * (x * x + y * y)) * vz)


@njit
def rotate_inv(q: Quat, v: Vec3) -> Vec3:
    """R(q)^T v."""
    return rotate((q[0], -q[1], -q[2], -q[3]), v)


@njit
def rotor_wrench_kernel(pp: np.ndarray, speeds: np.ndarray, tilts: np.ndarray) -> Wrench:
    """Sum over rotors of thrust and torque (arm moment plus drag), in FLU: (f, tau)."""
    fx = fy = fz = tx = ty = tz = 0.0
    for i in range(N_ROTORS):
        r = PP_ROTORS + PR_SIZE * i
        w = speeds[i]
        a = tilts[i]
        w2 = w * w
        c = w2 * math.cos(a)
        s = w2 * math.sin(a)
        fx += c * pp[r + PR_F_V] + s * pp[r + PR_F_L]
        fy += c * pp[r + PR_F_V + 1] + s * pp[r + PR_F_L + 1]
        fz += c * pp[r + PR_F_V + 2] + s * pp[r + PR_F_L + 2]
        tx += c * pp[r + PR_TAU_V] + s * pp[r + PR_TAU_L]
        ty += c * pp[r + PR_TAU_V + 1] + s * pp[r + PR_TAU_L + 1]
        tz += c * pp[r + PR_TAU_V + 2] + s * pp[r + PR_TAU_L + 2]
    return (fx, fy, fz, tx, ty, tz)


@njit
def rotor_lag_kernel(w_max: float, speed0: np.ndarray, cmd: np.ndarray, decay_up: float,
                     decay_down: float, out: np.ndarray) -> None:
    """First-order lag towards the command clamped to [0, w_max], exact over the hold."""
    for i in range(len(speed0)):
        w0 = speed0[i]
        c = cmd[i]
        c = 0.0 if c < 0.0 else (w_max if c > w_max else c)
        out[i] = c + (w0 - c) * (decay_up if c > w0 else decay_down)


@njit
def tilt_servo_kernel(tilt0: np.ndarray, cmd: np.ndarray, lim: float, out: np.ndarray) -> None:
    """Rate-limited servo: moves towards the command by at most `lim` (and lands on it
    exactly, so that a servo at rest has no kink in the next step)."""
    for i in range(len(tilt0)):
        a0, c = tilt0[i], cmd[i]
        d = c - a0
        out[i] = a0 + lim if d > lim else (a0 - lim if d < -lim else c)


@njit
def derivative_kernel(pp: np.ndarray, x: tuple[float, ...], wrench: tuple[float, ...]
                      ) -> tuple[float, ...]:
    """d/dt of (p, v, q, w) in ENU/FLU under a body wrench (f, tau)."""
    vx, vy, vz = x[3], x[4], x[5]
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    wx, wy, wz = x[10], x[11], x[12]
    fx, fy, fz, tx, ty, tz = wrench[0], wrench[1], wrench[2], wrench[3], wrench[4], wrench[5]
    inv_m = 1.0 / pp[PP_MASS]
    ax, ay, az = rotate((qw, qx, qy, qz), (fx * inv_m, fy * inv_m, fz * inv_m))
    jx, jy, jz = pp[PP_J], pp[PP_J + 1], pp[PP_J + 2]
    return (vx, vy, vz,
            ax, ay, az - pp[PP_G],
            0.5 * (-qx * wx - qy * wy - qz * wz),
            0.5 * (qw * wx + qy * wz - qz * wy),
            0.5 * (qw * wy - qx * wz + qz * wx),
            0.5 * (qw * wz + qx * wy - qy * wx),
            (tx - (jz - jy) * wy * wz) / jx,
            (ty - (jx - jz) * wz * wx) / jy,
            (tz - (jy - jx) * wx * wy) / jz)


@njit
def _axpy(x: tuple[float, ...], h: float, k: tuple[float, ...]) -> tuple[float, ...]:
    """x + h k for the 13 rigid-body states."""
    return (x[0] + h * k[0], x[1] + h * k[1], x[2] + h * k[2], x[3] + h * k[3],
            x[4] + h * k[4], x[5] + h * k[5], x[6] + h * k[6], x[7] + h * k[7],
            x[8] + h * k[8], x[9] + h * k[9], x[10] + h * k[10], x[11] + h * k[11],
            x[12] + h * k[12])


@njit
def _rk4_sum(x: float, h6: float, k1: float, k2: float, k3: float, k4: float) -> float:
    """x + h/6 (k1 + 2 (k2 + k3) + k4): one state's RK4 update."""
    return x + h6 * (k1 + 2.0 * (k2 + k3) + k4)


@njit
def _rk4(pp: np.ndarray, x: tuple[float, ...], h: float, wa: tuple[float, ...],
         wm: tuple[float, ...], wb: tuple[float, ...]) -> tuple[float, ...]:
    """One classical RK4 step of length h; wrench at the start, midpoint and end."""
    hh = 0.5 * h
    k1 = derivative_kernel(pp, x, wa)
    k2 = derivative_kernel(pp, _axpy(x, hh, k1), wm)
    k3 = derivative_kernel(pp, _axpy(x, hh, k2), wm)
    k4 = derivative_kernel(pp, _axpy(x, h, k3), wb)
    h6 = h / 6.0
    return (_rk4_sum(x[0], h6, k1[0], k2[0], k3[0], k4[0]),
            _rk4_sum(x[1], h6, k1[1], k2[1], k3[1], k4[1]),
            _rk4_sum(x[2], h6, k1[2], k2[2], k3[2], k4[2]),
            _rk4_sum(x[3], h6, k1[3], k2[3], k3[3], k4[3]),
            _rk4_sum(x[4], h6, k1[4], k2[4], k3[4], k4[4]),
            _rk4_sum(x[5], h6, k1[5], k2[5], k3[5], k4[5]),
            _rk4_sum(x[6], h6, k1[6], k2[6], k3[6], k4[6]),
            _rk4_sum(x[7], h6, k1[7], k2[7], k3[7], k4[7]),
            _rk4_sum(x[8], h6, k1[8], k2[8], k3[8], k4[8]),
            _rk4_sum(x[9], h6, k1[9], k2[9], k3[9], k4[9]),
            _rk4_sum(x[10], h6, k1[10], k2[10], k3[10], k4[10]),
            _rk4_sum(x[11], h6, k1[11], k2[11], k3[11], k4[11]),
            _rk4_sum(x[12], h6, k1[12], k2[12], k3[12], k4[12]))


@njit
def with_disturbance(pp: np.ndarray, dist: np.ndarray, r: tuple[float, ...],
                     t_s: float) -> tuple[float, ...]:
    """The rotor wrench r plus the disturbances' (sitl.disturbance) at t_s."""
    if pp[PP_DIST_ACTIVE] == 0.0:
        return r
    f, t = disturbance_kernel(dist, t_s - pp[PP_DIST_T0])
    return (r[0] + f[0], r[1] + f[1], r[2] + f[2], r[3] + t[0], r[4] + t[1], r[5] + t[2])


@njit
def flight_force_kernel(pp: np.ndarray, dist: np.ndarray, actuators: np.ndarray, t_s: float,
                        mass: float) -> tuple[float, float, float]:
    """The rotor and disturbance force per mass (FLU) at t_s of the actuators' state
    (N_ROTORS speeds, then N_ROTORS tilts): an accelerometer's reading in flight."""
    r = rotor_wrench_kernel(pp, actuators[:N_ROTORS], actuators[N_ROTORS:])
    w = with_disturbance(pp, dist, r, t_s)
    return (w[0] / mass, w[1] / mass, w[2] / mass)


@njit
def _wrench_after(pp: np.ndarray, speed0: np.ndarray, tilt0: np.ndarray, cmd: np.ndarray,
                  tau_s: float) -> tuple[float, ...]:
    """Rotor wrench on the exact (lagged) actuator trajectory tau_s into the step."""
    sp, ti = np.empty(N_ROTORS), np.empty(N_ROTORS)
    rotor_lag_kernel(pp[PP_WMAX], speed0, cmd[PC_SPEED:PC_SPEED + N_ROTORS],
                     math.exp(-tau_s / pp[PP_TAU_UP]), math.exp(-tau_s / pp[PP_TAU_DOWN]), sp)
    tilt_servo_kernel(tilt0, cmd[PC_TILT:PC_TILT + N_ROTORS], pp[PP_TILT_RATE] * tau_s, ti)
    return rotor_wrench_kernel(pp, sp, ti)


# C901 (21 > 12): one compiled physics step, its branches the piecewise RK4's sub-intervals
# and the ground contact; a helper kernel per branch would cost a call per piece in the
# loop that dominates a flight's time, for the same arithmetic.
@njit
def step_kernel(pp: np.ndarray, dist: np.ndarray, s: np.ndarray,  # noqa: C901
                cmd: np.ndarray, out: np.ndarray) -> int:
    """Advance the state row s (PLANT_STATE) one step of dt_us with the command cmd
    (PLANT_COMMAND) held, into out; returns the number of RK4 steps taken (one per smooth
    piece).

    A tilt servo that reaches its command inside the step has a kink in its trajectory at
    that instant; the step is then integrated piecewise, one RK4 step per sub-interval
    between kinks, so that every RK4 step sees a smooth actuator trajectory.
    """
    dt_us = pp[PP_DT_US]
    h = dt_us * 1e-6
    t0 = s[PS_TIME] * 1e-6
    speed0, tilt0 = s[PS_SPEED:PS_SPEED + N_ROTORS], s[PS_TILT:PS_TILT + N_ROTORS]
    sp_end, ti_end = out[PS_SPEED:PS_SPEED + N_ROTORS], out[PS_TILT:PS_TILT + N_ROTORS]
    speed_cmd, tilt_cmd = cmd[PC_SPEED:PC_SPEED + N_ROTORS], cmd[PC_TILT:PC_TILT + N_ROTORS]
    kinks = np.empty(N_ROTORS)
    n_kinks = 0
    w_max = pp[PP_WMAX]
    if pp[PP_IDEAL] != 0.0:
        for i in range(N_ROTORS):
            c = speed_cmd[i]
            sp_end[i] = 0.0 if c < 0.0 else (w_max if c > w_max else c)
            ti_end[i] = tilt_cmd[i]
        r0 = rotor_wrench_kernel(pp, sp_end, ti_end)
        r2 = r0
    else:
        rotor_lag_kernel(w_max, speed0, speed_cmd, pp[PP_DECAY_UP], pp[PP_DECAY_DOWN], sp_end)
        rate = pp[PP_TILT_RATE]
        lim = rate * h
        for i in range(N_ROTORS):
            a0, c = tilt0[i], tilt_cmd[i]
            d = c - a0
            if d > lim:
                ti_end[i] = a0 + lim
            elif d < -lim:
                ti_end[i] = a0 - lim
            else:
                ti_end[i] = c
                if d != 0.0:
                    t_k = abs(d) / rate
                    if t_k < h:  # t_k = h (to rounding) is the end of the step, no kink
                        kinks[n_kinks] = t_k
                        n_kinks += 1
        r0 = rotor_wrench_kernel(pp, speed0, tilt0)
        r2 = rotor_wrench_kernel(pp, sp_end, ti_end)
    w2 = with_disturbance(pp, dist, r2, t0 + h)
    out[PS_TIME] = s[PS_TIME] + dt_us

    q = (s[PS_Q], s[PS_Q + 1], s[PS_Q + 2], s[PS_Q + 3])
    if s[PS_LANDED] != 0.0 and pp[PP_GROUND] != 0.0:
        # Resting: stays unless the net vertical force lifts it off.
        fz_world = rotate(q, (w2[0], w2[1], w2[2]))[2] - pp[PP_MASS] * pp[PP_G]
        if fz_world <= 0.0:
            for j in range(3):
                out[PS_P + j] = s[PS_P + j]
            for j in range(4):
                out[PS_Q + j] = s[PS_Q + j]
            for j in _AT_REST:
                out[j] = 0.0
            out[PS_LANDED] = 1.0
            return 0

    x = (s[PS_P], s[PS_P + 1], s[PS_P + 2], s[PS_V], s[PS_V + 1], s[PS_V + 2],
         s[PS_Q], s[PS_Q + 1], s[PS_Q + 2], s[PS_Q + 3], s[PS_W], s[PS_W + 1], s[PS_W + 2])
    w0 = with_disturbance(pp, dist, r0, t0)
    pieces = 1
    if n_kinks == 0:
        # No kink inside the step: the actuator trajectory is smooth, one RK4 step.
        if pp[PP_IDEAL] != 0.0:
            r1 = r0
        else:
            sp_mid, ti_mid = np.empty(N_ROTORS), np.empty(N_ROTORS)
            rotor_lag_kernel(w_max, speed0, speed_cmd, pp[PP_DECAY_HALF_UP],
                             pp[PP_DECAY_HALF_DOWN], sp_mid)
            tilt_servo_kernel(tilt0, tilt_cmd, 0.5 * pp[PP_TILT_RATE] * h, ti_mid)
            r1 = rotor_wrench_kernel(pp, sp_mid, ti_mid)
        y = _rk4(pp, x, h, w0, with_disturbance(pp, dist, r1, t0 + 0.5 * h), w2)
    else:
        # Piecewise RK4 over [0, k_1], [k_1, k_2], ..., [k_n, h], k_j the kink instants;
        # the wrench at a sub-interval's end is the next one's start. In closed loop this
        # is frequent: a servo that keeps up with its command reaches each new one early
        # in the first physics step of the control period.
        ends = np.sort(kinks[:n_kinks])
        y, a, wa = x, 0.0, w0
        pieces = 0
        for j in range(n_kinks + 1):
            b = ends[j] if j < n_kinks else h
            if b <= a:
                continue  # servos reaching their commands at the same instant
            m = 0.5 * (a + b)
            wm = with_disturbance(pp, dist, _wrench_after(pp, speed0, tilt0, cmd, m), t0 + m)
            wb = (w2 if b == h else
                  with_disturbance(pp, dist, _wrench_after(pp, speed0, tilt0, cmd, b), t0 + b))
            y = _rk4(pp, y, b - a, wa, wm, wb)
            pieces += 1
            a, wa = b, wb
    qn = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    for j in range(4):
        out[PS_Q + j] = y[6 + j] / qn
    if pp[PP_GROUND] != 0.0 and y[2] < 0.0:
        out[PS_P], out[PS_P + 1], out[PS_P + 2] = y[0], y[1], 0.0
        for j in _AT_REST:
            out[j] = 0.0
        out[PS_LANDED] = 1.0
    else:
        for j in range(3):
            out[PS_P + j] = y[j]
            out[PS_V + j] = y[3 + j]
            out[PS_W + j] = y[10 + j]
        out[PS_LANDED] = 0.0
    return pieces


@njit
def steps_kernel(pp: np.ndarray, dist: np.ndarray, s: np.ndarray, cmd: np.ndarray,
                 out: np.ndarray) -> None:
    """len(out) steps from the state row s under the held command: row k of out is the
    state after k + 1 steps."""
    step_kernel(pp, dist, s, cmd, out[0])
    for k in range(1, out.shape[0]):
        step_kernel(pp, dist, out[k - 1], cmd, out[k])
