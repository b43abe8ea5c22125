"""POSCTL: a pilot's sticks (MANUAL_CONTROL) move the position and yaw set-point; pure, no I/O.

MANUAL_CONTROL as QGroundControl's virtual joystick sends it to PX4: x = forward (pitch
stick), y = right (roll stick), r = yaw clockwise, each -1000..1000, and z = throttle
0..1000 with 500 at the centre (PX4's convention for position and altitude modes: the centre
holds the altitude); INT16_MAX marks an axis that is not given (taken as centred). After a
dead zone of `DEADZONE` at the centre, deflection d (-1..1) maps linearly to a set-point
velocity, as PX4's position mode does without its expo curve:

    horizontal: (forward, right) d * speed_xy_m_s along the set-point's heading (a diagonal
                deflection is scaled back to at most speed_xy_m_s)
    vertical:   up d * speed_up_m_s, down d * speed_down_m_s
    yaw:        d * yaw_rate_deg_s about the world vertical (clockwise seen from above)

The set-point's velocity follows that target within the acceleration limits (acc_xy_m_s2
horizontally, acc_up_m_s2 / acc_down_m_s2 vertically, yaw_acc_deg_s2), and its position
integrates the velocity exactly (constant acceleration over each period). Sticks centred:
the velocity brakes to zero at the acceleration limit and the set-point holds where it
stopped; a stick held for T seconds at a deflection giving speed V moves the set-point V T
(the ramp up and the braking cancel). The set-point never leads the vehicle by more than
`LEAD_M`. The attitude is the one at entry, turned about the world vertical by the yaw
integrated so far (an omnidirectional vehicle keeps its roll and pitch in POSCTL).

Flyable set-points (`fit_envelope`): the accelerations are halved until the nominal wrench of
every combination of their limits (and of the yaw rate and acceleration), at the entry
attitude turned to any yaw, fits the vehicle's rotor envelope (`fcu.feasibility`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from common.config import VehicleConfig
from common.frames import ned_to_enu
from fcu.dualquat import Quat, Vec3, q_exp, q_mul, q_rotate, q_rotate_inv
from fcu.feasibility import envelope
from fcu.tracker import Reference

STICK_MAX = 1000  # MANUAL_CONTROL x, y, r: -1000..1000
THROTTLE_CENTRE = 500  # MANUAL_CONTROL z: 0..1000, 500 holds the altitude (PX4)
INVALID_AXIS = 32767  # INT16_MAX: the axis is not given
DEADZONE = 0.05  # share of the deflection around the centre that commands nothing
LEAD_M = 1.0  # the set-point stays within this distance of the vehicle
MAX_DT_S = 0.1  # a longer gap between two samples integrates as this long
FIT_HALVINGS = 8  # `fit_envelope` halves the accelerations at most this many times


class Sticks(NamedTuple):
    """Stick deflections, each -1..1: forward, right, up (throttle from its centre), yaw
    (clockwise)."""

    forward: float = 0.0
    right: float = 0.0
    up: float = 0.0
    yaw: float = 0.0


CENTRED = Sticks()


def sticks_from_manual_control(x: int, y: int, z: int, r: int) -> Sticks:
    """MANUAL_CONTROL's x, y, z, r as deflections (module docstring); values beyond the
    ranges are clamped, INT16_MAX is a centred axis."""
    def axis(v: int) -> float:
        if v == INVALID_AXIS:
            return 0.0
        return max(-1.0, min(1.0, v / STICK_MAX))

    up = 0.0 if z == INVALID_AXIS else \
        max(-1.0, min(1.0, (z - THROTTLE_CENTRE) / (STICK_MAX - THROTTLE_CENTRE)))
    return Sticks(axis(x), axis(y), up, axis(r))


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
    NED yaw turned since, and the yaw rate."""

    t_us: int
    p_enu_m: Vec3
    v_enu_m_s: Vec3
    q0_enu_flu: Quat
    yaw_ned_rad: float = 0.0
    yaw_rate_ned_rad_s: float = 0.0

    @property
    def q_enu_flu(self) -> Quat:
        return yawed(self.q0_enu_flu, self.yaw_ned_rad)


def start(t_us: int, p_enu_m: Vec3, q_enu_flu: Quat) -> ManualSetpoint:
    """Entering POSCTL: still, at the given pose."""
    return ManualSetpoint(t_us, p_enu_m, (0.0, 0.0, 0.0), q_enu_flu)


def advance(sp: ManualSetpoint, t_us: int, sticks: Sticks, s: StickSettings,
            p_vehicle_enu_m: Vec3 | None = None) -> tuple[ManualSetpoint, Reference]:
    """The set-point at t_us after holding `sticks` since sp.t_us, and its reference
    (position, attitude, velocity, acceleration, body rate and its derivative)."""
    dt = min(max((t_us - sp.t_us) * 1e-6, 0.0), MAX_DT_S)
    q = sp.q_enu_flu
    v_ned, yaw_rate_target = stick_velocity(sticks, heading_ned(q), s)
    target = ned_to_enu(v_ned)
    v = sp.v_enu_m_s
    dvx, dvy = target[0] - v[0], target[1] - v[1]
    dvz = target[2] - v[2]
    dh = math.hypot(dvx, dvy)
    lim = s.acc_xy_m_s2 * dt
    if dh > lim:
        dvx, dvy = dvx * lim / dh, dvy * lim / dh
    dvz = max(-s.acc_down_m_s2 * dt, min(s.acc_up_m_s2 * dt, dvz))
    dyr = yaw_rate_target - sp.yaw_rate_ned_rad_s
    ylim = math.radians(s.yaw_acc_deg_s2) * dt
    dyr = max(-ylim, min(ylim, dyr))
    v_new = (v[0] + dvx, v[1] + dvy, v[2] + dvz)
    p = sp.p_enu_m
    p_new = (p[0] + 0.5 * (v[0] + v_new[0]) * dt, p[1] + 0.5 * (v[1] + v_new[1]) * dt,
             p[2] + 0.5 * (v[2] + v_new[2]) * dt)
    if p_vehicle_enu_m is not None:
        d = (p_new[0] - p_vehicle_enu_m[0], p_new[1] - p_vehicle_enu_m[1],
             p_new[2] - p_vehicle_enu_m[2])
        lead = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if lead > LEAD_M:
            k = LEAD_M / lead
            p_new = (p_vehicle_enu_m[0] + d[0] * k, p_vehicle_enu_m[1] + d[1] * k,
                     p_vehicle_enu_m[2] + d[2] * k)
    yaw_rate = sp.yaw_rate_ned_rad_s + dyr
    yaw = sp.yaw_ned_rad + 0.5 * (sp.yaw_rate_ned_rad_s + yaw_rate) * dt
    a = (dvx / dt, dvy / dt, dvz / dt) if dt > 0.0 else (0.0, 0.0, 0.0)
    yaw_acc = dyr / dt if dt > 0.0 else 0.0
    new = ManualSetpoint(t_us, p_new, v_new, sp.q0_enu_flu, yaw, yaw_rate)
    q_new = new.q_enu_flu
    # a NED yaw rate turns about the ENU vertical the other way
    omega = q_rotate_inv(q_new, (0.0, 0.0, -yaw_rate))
    omega_dot = q_rotate_inv(q_new, (0.0, 0.0, -yaw_acc))
    return new, Reference(p_new, q_new, v_new, a, omega, omega_dot)


def _fits(vehicle: VehicleConfig, q0: Quat, s: StickSettings) -> bool:
    """Every corner of the acceleration and yaw limits, at q0 turned to any of 12 yaws."""
    env = envelope(vehicle)
    acc: list[Vec3] = []  # world accelerations
    rate: list[float] = []  # world yaw rates (about the ENU vertical) and their derivatives
    rate_dot: list[float] = []
    wz, wdz = math.radians(s.yaw_rate_deg_s), math.radians(s.yaw_acc_deg_s2)
    for k in range(8):
        ang = k * math.pi / 4.0
        for az in (s.acc_up_m_s2, -s.acc_down_m_s2, 0.0):
            for sign in (1.0, -1.0):
                acc.append((s.acc_xy_m_s2 * math.cos(ang), s.acc_xy_m_s2 * math.sin(ang), az))
                rate.append(sign * wz)
                rate_dot.append(sign * wdz)
    a: Any = tuple(np.array([x[i] for x in acc]) for i in range(3))
    zero: Any = (0.0, 0.0, 0.0)
    for j in range(12):
        q = yawed(q0, j * math.pi / 6.0)
        up = q_rotate_inv(q, (0.0, 0.0, 1.0))  # the world vertical in the body frame
        w: Any = tuple(up[i] * np.array(rate) for i in range(3))
        wd: Any = tuple(up[i] * np.array(rate_dot) for i in range(3))
        if float(env.speeds(Reference(zero, q, zero, a, w, wd)).max()) > env.limit:
            return False
    return True


def fit_envelope(s: StickSettings, vehicle: VehicleConfig | None, q0: Quat) -> StickSettings:
    """`s` with its accelerations (and yaw rate) halved until the vehicle can fly every
    corner of them at the attitude q0 turned to any yaw; as it is without a vehicle. When
    nothing fits (hovering there already exceeds the envelope) the smallest one tried."""
    if vehicle is None:
        return s
    trial = s
    for _ in range(FIT_HALVINGS):
        if _fits(vehicle, q0, trial):
            return trial
        trial = replace(trial, acc_xy_m_s2=trial.acc_xy_m_s2 / 2,
                        acc_up_m_s2=trial.acc_up_m_s2 / 2,
                        acc_down_m_s2=trial.acc_down_m_s2 / 2,
                        yaw_rate_deg_s=trial.yaw_rate_deg_s / 2,
                        yaw_acc_deg_s2=trial.yaw_acc_deg_s2 / 2)
    return trial
