"""POSCTL: a pilot's sticks (MANUAL_CONTROL) move the position and yaw set-point; pure, no I/O.

The sticks come as deflections (`Sticks`: forward, right, up from the throttle's centre, yaw
clockwise, each -1..1), decoded from MANUAL_CONTROL by the FCU's MAVLink edge
(`fcu.edge.setpoint_wire.sticks_from_manual_control`). After a dead zone of `DEADZONE` at the
centre, deflection d (-1..1) maps linearly to a set-point velocity, as PX4's position mode
does without its expo curve:

    horizontal: (forward, right) d * speed_xy_m_s along the set-point's heading (a diagonal
                deflection is scaled back to at most speed_xy_m_s)
    vertical:   up d * speed_up_m_s, down d * speed_down_m_s
    yaw:        d * yaw_rate_deg_s about the world vertical (clockwise seen from above)

The set-point's velocity follows that target with a jerk-limited acceleration, as PX4's and
ArduPilot's jerk-limited shapers do (ArduPilot's `shape_vel_accel`): the acceleration wanted
is `sqrt_controller` of the velocity error (second-order limit the jerk; gain GAIN_RATIO
jerk / acceleration limit: ArduPilot's ratio 1 leaves an exponential tail that creeps 0.4 m
after braking from 5 m/s), at most acc_xy_m_s2 horizontally and acc_up_m_s2 / acc_down_m_s2
vertically (yaw_acc_deg_s2 in yaw), and the acceleration moves towards it by at most the
jerk times the period (jerk_m_s3: PX4's MPC_JERK_MAX; yaw_jerk_deg_s3). The acceleration is
thus continuous: an acceleration step is a step of every tilt angle, which a rate-limited
servo cannot take. Position and velocity integrate the piecewise-linear acceleration
exactly. Sticks centred: the velocity brakes to zero and the set-point holds where it
stopped; a stick held for T seconds at a deflection giving speed V moves the set-point about
V T (the ramp up and the braking nearly cancel: within 2 % for 2 s at 5 m/s). The set-point
never leads the vehicle by more than `LEAD_M`. The attitude is the one at entry, turned
about the world vertical by the yaw integrated so far (an omnidirectional vehicle keeps its
roll and pitch in POSCTL).

Flyable set-points (`fit_envelope`): the accelerations (and the yaw rate and acceleration) are
halved until the nominal wrench of every combination of their limits, at the entry attitude
turned to any yaw, fits the vehicle's rotor envelope (`fcu.envelope.feasibility`); then the jerks
and the yaw rate are cut until the tilt rates they cause there (the gradients of the allocated
tilts in the acceleration, the yaw and the yaw acceleration, by central differences) keep
within the tilt servos' share TILT_MARGIN: half of it for the jerk, a quarter each for the yaw
rate and the yaw jerk. Where a corner takes a rotor's thrust near zero its tilt swings
fast (the gradients grow without bound): while the jerk or yaw rate left would be below
JERK_FLOOR_M_S3 or YAW_FLOOR_DEG_S, the accelerations are halved again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from common.config.scenario import VehicleConfig
from common.frames import ned_to_enu
from common.jit import njit
from fcu.control.dualquat import Quat, Vec3, q_exp, q_mul, q_rotate, q_rotate_inv
from fcu.control.wrench import wrench_matrix
from fcu.envelope.feasibility import envelope
from fcu.stages import Reference

DEADZONE = 0.05  # share of the deflection around the centre that commands nothing
LEAD_M = 1.0  # the set-point stays within this distance of the vehicle
MAX_DT_S = 0.1  # a longer gap between two samples integrates as this long
FIT_HALVINGS = 8  # `fit_envelope` halves the accelerations at most this many times
GAIN_RATIO = 4.0  # the shaper's gain near zero, times jerk / acceleration (ArduPilot: 1)
REST_M_S, REST_M_S2 = 1e-6, 1e-5  # with the sticks centred, a velocity and an acceleration
REST_RAD_S, REST_RAD_S2 = 1e-6, 1e-5  # below these are rest (and the yaw's)
GRADIENT_STEP = 1e-4  # m/s^2 and rad (/s^2): `_tilt_gradients`' central differences
JERK_SHARE, YAW_RATE_SHARE, YAW_JERK_SHARE = 0.5, 0.25, 0.25  # of the tilt rate budget
JERK_FLOOR_M_S3, YAW_FLOOR_DEG_S = 1.0, 10.0  # below these, the accelerations are halved


class Sticks(NamedTuple):
    """Stick deflections, each -1..1: forward, right, up (throttle from its centre), yaw
    (clockwise)."""

    forward: float = 0.0
    right: float = 0.0
    up: float = 0.0
    yaw: float = 0.0


CENTRED = Sticks()


@dataclass(frozen=True)
class StickSettings:
    """Full-deflection speeds and the acceleration limits of POSCTL (PX4's MPC_* names)."""

    speed_xy_m_s: float = 5.0  # MPC_VEL_MANUAL
    speed_up_m_s: float = 3.0  # MPC_Z_VEL_MAX_UP
    speed_down_m_s: float = 1.5  # MPC_Z_VEL_MAX_DN
    acc_xy_m_s2: float = 3.0  # MPC_ACC_HOR
    acc_up_m_s2: float = 3.0  # MPC_ACC_UP_MAX
    acc_down_m_s2: float = 3.0  # MPC_ACC_DOWN_MAX
    yaw_rate_deg_s: float = 90.0  # MPC_MAN_Y_MAX
    yaw_acc_deg_s2: float = 180.0
    jerk_m_s3: float = 8.0  # MPC_JERK_MAX
    yaw_jerk_deg_s3: float = 720.0


def deflection(s: float) -> float:
    """A stick value (-1..1) after the dead zone, rescaled to -1..1."""
    mag = abs(s)
    if not math.isfinite(mag) or mag <= DEADZONE:
        return 0.0
    return math.copysign(min(1.0, (mag - DEADZONE) / (1.0 - DEADZONE)), s)


def stick_velocity(sticks: Sticks, heading_ned_rad: float, s: StickSettings
                   ) -> tuple[Vec3, float]:
    """(target velocity NED m/s, target yaw rate rad/s, NED: clockwise from above)."""
    f, r = deflection(sticks.forward), deflection(sticks.right)
    n = math.hypot(f, r)
    if n > 1.0:
        f, r = f / n, r / n
    c, si = math.cos(heading_ned_rad), math.sin(heading_ned_rad)
    vn = (f * c - r * si) * s.speed_xy_m_s
    ve = (f * si + r * c) * s.speed_xy_m_s
    u = deflection(sticks.up)
    v_up = u * (s.speed_up_m_s if u > 0.0 else s.speed_down_m_s)
    return (vn, ve, -v_up), deflection(sticks.yaw) * math.radians(s.yaw_rate_deg_s)


@njit
def yawed(q0: Quat, yaw_ned_rad: float) -> Quat:
    """q0 turned about the world vertical by a NED yaw (clockwise from above)."""
    return q_mul(q_exp((0.0, 0.0, -yaw_ned_rad)), q0)


def heading_ned(q_enu_flu: Quat) -> float:
    """NED heading of the body's forward axis projected on the horizontal (0 = north); 0
    when the forward axis points (nearly) straight up or down."""
    e, n, _ = q_rotate(q_enu_flu, (1.0, 0.0, 0.0))
    if math.hypot(e, n) < 1e-3:
        return 0.0
    return math.atan2(e, n)


class ManualSetpoint(NamedTuple):
    """The POSCTL set-point at t_us (ENU): position, velocity, the attitude at entry and the
    NED yaw turned since, the yaw rate, the acceleration and the yaw acceleration."""

    t_us: int
    p_enu_m: Vec3
    v_enu_m_s: Vec3
    q0_enu_flu: Quat
    yaw_ned_rad: float = 0.0
    yaw_rate_ned_rad_s: float = 0.0
    a_enu_m_s2: Vec3 = (0.0, 0.0, 0.0)
    yaw_acc_ned_rad_s2: float = 0.0

    @property
    def q_enu_flu(self) -> Quat:
        return yawed(self.q0_enu_flu, self.yaw_ned_rad)


def start(t_us: int, p_enu_m: Vec3, q_enu_flu: Quat) -> ManualSetpoint:
    """Entering POSCTL: still, at the given pose."""
    return ManualSetpoint(t_us, p_enu_m, (0.0, 0.0, 0.0), q_enu_flu)


def continuing(t_us: int, ref: Reference) -> ManualSetpoint:
    """Entering POSCTL at the reference flown: its pose, and its velocity, acceleration and
    the yaw part of its body rate and of that rate's derivative (the world's vertical
    component, NED: clockwise), which the shaper takes from there to what the sticks ask
    (`advance`); from a still reference, `start`'s. Started still from a moving reference
    instead, its velocity stepped to zero."""
    w = q_rotate(ref.q_enu_flu, ref.omega_flu_rad_s)
    w_dot = q_rotate(ref.q_enu_flu, ref.omega_dot_flu_rad_s2)  # d/dt (R w) = R dw/dt
    return ManualSetpoint(t_us, ref.p_enu_m, ref.v_enu_m_s, ref.q_enu_flu, 0.0, 0.0 - w[2],
                          ref.a_enu_m_s2, 0.0 - w_dot[2])


def sqrt_controller(error: float, gain: float, limit: float, dt: float) -> float:
    """ArduPilot's sqrt_controller for error >= 0: the rate that brings `error` to zero,
    gain * error near zero, sqrt(2 limit (error - limit / 2 gain^2)) beyond limit / gain^2,
    and at most error / dt (the step does not overshoot)."""
    linear = limit / (gain * gain)
    rate = math.sqrt(2.0 * limit * (error - 0.5 * linear)) if error > linear else gain * error
    return min(rate, error / dt) if dt > 0.0 else rate


def _shape(err: float, a: float, acc_pos: float, acc_neg: float, jerk: float, dt: float
           ) -> float:
    """One axis of `shape_vel_accel`: the acceleration after dt for a velocity error err."""
    acc = acc_pos if err > 0.0 else acc_neg
    want = math.copysign(min(sqrt_controller(abs(err), GAIN_RATIO * jerk / acc, jerk, dt),
                             acc), err)
    return a + max(-jerk * dt, min(jerk * dt, want - a))


def advance(sp: ManualSetpoint, t_us: int, sticks: Sticks, s: StickSettings,
            p_vehicle_enu_m: Vec3 | None = None) -> tuple[ManualSetpoint, Reference]:
    """The set-point at t_us after holding `sticks` since sp.t_us, and its reference
    (position, attitude, velocity, acceleration, body rate and its derivative)."""
    dt = min(max((t_us - sp.t_us) * 1e-6, 0.0), MAX_DT_S)
    q = sp.q_enu_flu
    v_ned, yaw_rate_target = stick_velocity(sticks, heading_ned(q), s)
    target = ned_to_enu(v_ned)
    v, a = sp.v_enu_m_s, sp.a_enu_m_s2
    # horizontal: the error's direction, its size shaped, the change limited as a vector
    ex, ey = target[0] - v[0], target[1] - v[1]
    eh = math.hypot(ex, ey)
    if eh > 0.0:
        mag = min(sqrt_controller(eh, GAIN_RATIO * s.jerk_m_s3 / s.acc_xy_m_s2, s.jerk_m_s3,
                                  dt), s.acc_xy_m_s2)
        want_x, want_y = ex / eh * mag, ey / eh * mag
    else:
        want_x = want_y = 0.0
    dax, day = want_x - a[0], want_y - a[1]
    dah = math.hypot(dax, day)
    if dah > s.jerk_m_s3 * dt:  # so dah > 0
        dax, day = dax * s.jerk_m_s3 * dt / dah, day * s.jerk_m_s3 * dt / dah
    az = _shape(target[2] - v[2], a[2], s.acc_up_m_s2, s.acc_down_m_s2, s.jerk_m_s3, dt)
    a_new = (a[0] + dax, a[1] + day, az)
    v_new = (v[0] + 0.5 * (a[0] + a_new[0]) * dt, v[1] + 0.5 * (a[1] + a_new[1]) * dt,
             v[2] + 0.5 * (a[2] + a_new[2]) * dt)
    if not any(target) and max(map(abs, v_new)) < REST_M_S and \
            max(map(abs, a_new)) < REST_M_S2:
        v_new = a_new = (0.0, 0.0, 0.0)  # at rest: no creep from the shaper's linear tail
    p = sp.p_enu_m
    h = dt * dt / 6.0
    p_new = (p[0] + v[0] * dt + (2.0 * a[0] + a_new[0]) * h,
             p[1] + v[1] * dt + (2.0 * a[1] + a_new[1]) * h,
             p[2] + v[2] * dt + (2.0 * a[2] + a_new[2]) * h)
    if p_vehicle_enu_m is not None:
        d = (p_new[0] - p_vehicle_enu_m[0], p_new[1] - p_vehicle_enu_m[1],
             p_new[2] - p_vehicle_enu_m[2])
        lead = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if lead > LEAD_M:
            k = LEAD_M / lead
            p_new = (p_vehicle_enu_m[0] + d[0] * k, p_vehicle_enu_m[1] + d[1] * k,
                     p_vehicle_enu_m[2] + d[2] * k)
    yaw_acc_max = math.radians(s.yaw_acc_deg_s2)
    yaw_acc = _shape(yaw_rate_target - sp.yaw_rate_ned_rad_s, sp.yaw_acc_ned_rad_s2,
                     yaw_acc_max, yaw_acc_max, math.radians(s.yaw_jerk_deg_s3), dt)
    yaw_rate = sp.yaw_rate_ned_rad_s + 0.5 * (sp.yaw_acc_ned_rad_s2 + yaw_acc) * dt
    if yaw_rate_target == 0.0 and abs(yaw_rate) < REST_RAD_S and abs(yaw_acc) < REST_RAD_S2:
        yaw_rate = yaw_acc = 0.0
    yaw = sp.yaw_ned_rad + sp.yaw_rate_ned_rad_s * dt + \
        (2.0 * sp.yaw_acc_ned_rad_s2 + yaw_acc) * h
    new = ManualSetpoint(t_us, p_new, v_new, sp.q0_enu_flu, yaw, yaw_rate, a_new, yaw_acc)
    q_new = new.q_enu_flu
    # a NED yaw rate turns about the ENU vertical the other way
    omega = q_rotate_inv(q_new, (0.0, 0.0, -yaw_rate))
    omega_dot = q_rotate_inv(q_new, (0.0, 0.0, -yaw_acc))
    return new, Reference(p_new, q_new, v_new, a_new, omega, omega_dot)


def _corners(s: StickSettings) -> list[Vec3]:
    """The world accelerations at the corners of the limits: 8 directions x up, down, level."""
    out: list[Vec3] = []
    for k in range(8):
        ang = k * math.pi / 4.0
        for az in (s.acc_up_m_s2, -s.acc_down_m_s2, 0.0):
            out.append((s.acc_xy_m_s2 * math.cos(ang), s.acc_xy_m_s2 * math.sin(ang), az))
    return out


def _floats(q: Quat) -> Quat:
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def _speeds_of(om: np.ndarray) -> np.ndarray:
    """Rotor speeds (samples x rotors) from Omega (`fcu.envelope.feasibility._speeds`)."""
    lat, ver = om[:, 0::2], om[:, 1::2]
    return np.asarray(np.sqrt(np.sqrt(lat * lat + ver * ver)))


@njit
def _corner_wrenches(m: float, g: float, inertia: Vec3, q0: Quat, j: int, acc: np.ndarray,
                     rate: np.ndarray, rate_dot: np.ndarray, out: np.ndarray) -> None:
    """The nominal wrenches `_fits` judges at yaw j (q0 turned by j pi / 6), one row per
    corner (world accelerations acc, 3 x n; yaw rates and their derivatives about the
    world vertical), by the expressions of the `Reference` it took, so the same values."""
    q = yawed(q0, j * math.pi / 6.0)
    up = q_rotate_inv(q, (0.0, 0.0, 1.0))  # the world vertical in the body frame
    n = rate.shape[0]
    q_rows, w, wd = np.empty((4, n)), np.empty((3, n)), np.empty((3, n))
    for k in range(n):
        for i in range(4):
            q_rows[i, k] = q[i]
        for i in range(3):
            w[i, k] = up[i] * rate[k]
            wd[i, k] = up[i] * rate_dot[k]
    wrench_matrix(m, g, inertia, q_rows, acc, w, wd, out)


def _fits(vehicle: VehicleConfig, q0: Quat, s: StickSettings) -> bool:
    """Every corner of the acceleration and yaw limits, at q0 turned to any of 12 yaws."""
    env = envelope(vehicle)
    wz, wdz = math.radians(s.yaw_rate_deg_s), math.radians(s.yaw_acc_deg_s2)
    acc = [a for a in _corners(s) for _ in (1.0, -1.0)]  # world accelerations
    # world yaw rates (about the ENU vertical) and their derivatives
    rate = np.array([sign * wz for _ in range(24) for sign in (1.0, -1.0)])
    rate_dot = np.array([sign * wdz for _ in range(24) for sign in (1.0, -1.0)])
    a = np.ascontiguousarray(np.array(acc).T)
    v, q = vehicle, _floats(q0)
    for j in range(12):
        wrench = np.empty((len(acc), 6))
        _corner_wrenches(v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2, q, j, a, rate,
                         rate_dot, wrench)
        if float(_speeds_of(wrench @ env.pinv_t).max()) > env.limit:
            return False
    return True


@njit
def _gradient_samples(q0: Quat, corners: np.ndarray, h: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The attitudes (4 x n), world accelerations and body rates' derivatives (3 x n) of
    `_tilt_gradients`' samples, in its order: 12 yaws x corners x its 10 steps (the
    acceleration's x, y, z, the yaw, the yaw acceleration, each + and - h); the
    expressions of the lists it built, so the same values."""
    n = 12 * corners.shape[0] * 10
    qs, acc, wd = np.empty((4, n)), np.empty((3, n)), np.empty((3, n))
    r = 0
    for j in range(12):
        q = yawed(q0, j * math.pi / 6.0)
        for c in range(corners.shape[0]):
            for step in range(10):
                d = h if step % 2 == 0 else -h
                da = (d if step < 2 else 0.0, d if 2 <= step < 4 else 0.0,
                      d if 4 <= step < 6 else 0.0)
                qr = yawed(q, d) if 6 <= step < 8 else q
                dy = d if step >= 8 else 0.0
                for i in range(4):
                    qs[i, r] = qr[i]
                for i in range(3):
                    acc[i, r] = corners[c, i] + da[i]
                wd[0, r], wd[1, r], wd[2, r] = q_rotate_inv(qr, (0.0, 0.0, -dy))
                r += 1
    return qs, acc, wd


def _tilts(vehicle: VehicleConfig, qs: np.ndarray, acc: np.ndarray, wd: np.ndarray
           ) -> np.ndarray:
    """The allocated tilt angles (samples x rotors) of the nominal wrench at attitudes qs
    (4 x n), world accelerations acc and body rates' derivatives wd (3 x n), no body rate."""
    v = vehicle
    wrench = np.empty((qs.shape[1], 6))
    wrench_matrix(v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2, qs, acc,
                  np.zeros((3, qs.shape[1])), wd, wrench)
    om = np.asarray(wrench @ envelope(vehicle).pinv_t)
    return np.asarray(np.arctan2(om[:, 0::2], om[:, 1::2]))


def _tilt_gradients(vehicle: VehicleConfig, q0: Quat, s: StickSettings
                    ) -> tuple[float, float, float]:
    """The largest tilt-angle gradients over the corners of `_fits` (and hover) at q0 turned
    to any of 12 yaws: in the world acceleration (rad per m/s^2, its norm), the yaw (rad per
    rad) and the yaw acceleration (rad per rad/s^2), by central differences."""
    h = GRADIENT_STEP
    corners = np.array([(0.0, 0.0, 0.0), *_corners(s)])
    tilt = _tilts(vehicle, *_gradient_samples(_floats(q0), corners, h)).reshape(
        -1, 10, vehicle.n_rotors)
    diff = np.angle(np.exp(1j * (tilt[:, 0::2] - tilt[:, 1::2]))) / (2.0 * h)  # (n, 5, rotors)
    g_acc = float(np.sqrt((diff[:, 0:3] ** 2).sum(axis=1)).max())
    return g_acc, float(np.abs(diff[:, 3]).max()), float(np.abs(diff[:, 4]).max())


def fit_rotors(s: StickSettings, vehicle: VehicleConfig, q0: Quat) -> StickSettings:
    """`s` with its accelerations (and yaw rate and acceleration) halved until the rotors
    fly every corner of them at q0 turned to any yaw (`_fits`), at most FIT_HALVINGS
    times."""
    trial = s
    for _ in range(FIT_HALVINGS):
        if _fits(vehicle, q0, trial):
            break
        trial = replace(trial, acc_xy_m_s2=trial.acc_xy_m_s2 / 2,
                        acc_up_m_s2=trial.acc_up_m_s2 / 2,
                        acc_down_m_s2=trial.acc_down_m_s2 / 2,
                        yaw_rate_deg_s=trial.yaw_rate_deg_s / 2,
                        yaw_acc_deg_s2=trial.yaw_acc_deg_s2 / 2)
    return trial


def fit_envelope(s: StickSettings, vehicle: VehicleConfig | None, q0: Quat) -> StickSettings:
    """`s` fitted to the rotors (`fit_rotors`), then its jerks and yaw rate cut to what the
    tilt servos follow there (module docstring); as it is without a vehicle. When nothing
    fits (hovering there already exceeds the envelope) the smallest one tried."""
    if vehicle is None:
        return s
    trial = fit_rotors(s, vehicle, q0)
    budget = envelope(vehicle).tilt_limit
    g_acc, g_yaw, g_yaw_acc = _tilt_gradients(vehicle, q0, trial)
    for _ in range(FIT_HALVINGS):  # where a corner's rotor thrust is near zero, its tilt
        if JERK_SHARE * budget / max(g_acc, 1e-9) >= JERK_FLOOR_M_S3 and \
                math.degrees(YAW_RATE_SHARE * budget / max(g_yaw, 1e-9)) >= YAW_FLOOR_DEG_S:
            break  # swings fast: go gentler
        trial = replace(trial, acc_xy_m_s2=trial.acc_xy_m_s2 / 2,
                        acc_up_m_s2=trial.acc_up_m_s2 / 2,
                        acc_down_m_s2=trial.acc_down_m_s2 / 2)
        g_acc, g_yaw, g_yaw_acc = _tilt_gradients(vehicle, q0, trial)
    return replace(
        trial,
        jerk_m_s3=min(trial.jerk_m_s3, JERK_SHARE * budget / max(g_acc, 1e-9)),
        yaw_rate_deg_s=min(trial.yaw_rate_deg_s,
                           math.degrees(YAW_RATE_SHARE * budget / max(g_yaw, 1e-9))),
        yaw_jerk_deg_s3=min(trial.yaw_jerk_deg_s3,
                            math.degrees(YAW_JERK_SHARE * budget / max(g_yaw_acc, 1e-9))))
