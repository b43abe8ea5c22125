"""OFFBOARD: the streamed set-point made into a reference the vehicle can fly; pure, no I/O.

SET_POSITION_TARGET_LOCAL_NED and SET_ATTITUDE_TARGET give a target pose, each part
optional, with optional velocity, acceleration and body-rate feed-forward, a few tens of
times a second. A sample holds from the control step at which it is first seen (its
"anchor"), extrapolated with its own feed-forward over the flight time tau since then:

    p_sp(tau) = p + v tau + a tau^2 / 2        q_sp(tau) = q (x) exp(omega tau)

A part the sample does not give is anchored where the reference is (velocity-only samples
fly the velocity; no attitude and no yaw keeps the attitude). The reference is the target
plus an offset:

    p_ref = p_sp + e                           q_ref = q_sp (x) exp(eps)

When a sample is first seen, e and eps (and their rates) take the values that keep the
reference continuous in pose, velocity and body rate; then they decay to zero as
ArduPilot's `sqrt_controller` shapes a correction: proportional (`GAIN_1_S`, `GAIN_ATT_1_S`)
near zero, the
braking curve sqrt(2 a |e|) beyond, never more than |e| / dt in a step. The correction's
rate is limited to the approach speeds and its change per step to the accelerations of
`StickSettings`: POSCTL's MPC_VEL_MANUAL horizontally, MPC_Z_VEL_MAX_UP / _DN, MPC_ACC_HOR,
MPC_ACC_UP_MAX / _DOWN_MAX, and a rotation about any axis at `ROTATION_RATE_DEG_S` and
`ROTATION_ACC_DEG_S2` (`limits`), all halved by `manual.fit_envelope` at OFFBOARD's entry
until the rotors can fly them.

So a stream that is a flyable trajectory (velocity and acceleration consistent with its
positions) is flown as streamed (e stays zero), and a step of any size is flown at bounded
speed and acceleration. Taken as a step of the tracker's error instead, a 10 m, 150 deg
step saturated the rotors for seconds and put the vehicle on the ground.

e is in ENU; eps is a rotation vector in the set-point's body frame (FLU), so the
reference's body rate is exp(eps)^-1 omega exp(eps) + J_r(eps) d eps/dt, with J_r the right
Jacobian of SO(3)'s exponential (J_r(eps) d eps/dt = d eps/dt while eps keeps its direction,
as it does once it decays); its derivative is taken as J_r(eps) d^2 eps/dt^2.

A new sample is seen at the step whose reference has just been computed from the one
before, and is anchored there: it shapes the reference from the next step on.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

from fcu.dualquat import Quat, Vec3, cross, q_conj, q_exp, q_log, q_mul, q_rotate_inv
from fcu.manual import StickSettings
from fcu.tracker import Reference

GAIN_1_S = 2.0  # position: the correction's gain near zero (ArduPilot's PSC_POS*_P is 1)
GAIN_ATT_1_S = 4.0  # attitude (ArduPilot's input time constant ATC_INPUT_TC is 0.15 s)
ROTATION_RATE_DEG_S = 90.0  # a rotation's approach rate, about any axis
ROTATION_ACC_DEG_S2 = 180.0
MAX_DT_S = 0.1  # a longer gap between two steps integrates as this long
SETTLED = 1e-12  # an offset and rate below this are zero
_ZERO: Vec3 = (0.0, 0.0, 0.0)


class Target(NamedTuple):
    """One offboard sample in ENU/FLU; `seq` changes with every sample received. None: the
    part is not given (anchored where the reference is)."""

    seq: int
    p_enu_m: Vec3 | None
    v_enu_m_s: Vec3
    a_enu_m_s2: Vec3
    q_enu_flu: Quat | None
    omega_flu_rad_s: Vec3


class Shaped(NamedTuple):
    """The shaper's state at t_us: the sample in force (seq, its anchor time and pose, its
    feed-forward), the offsets and their rates, and the reference it gave."""

    t_us: int
    seq: int
    anchor_us: int
    p_enu_m: Vec3
    v_enu_m_s: Vec3
    a_enu_m_s2: Vec3
    q_enu_flu: Quat
    omega_flu_rad_s: Vec3
    e_enu_m: Vec3
    de_enu_m_s: Vec3
    eps_rad: Vec3
    deps_rad_s: Vec3
    ref: Reference


def limits(sticks: StickSettings) -> StickSettings:
    """POSCTL's speeds and accelerations with the rotation limits of OFFBOARD's approach
    (not the yaw stick's MPC_MAN_Y_MAX, which may be 0)."""
    return replace(sticks, yaw_rate_deg_s=ROTATION_RATE_DEG_S,
                   yaw_acc_deg_s2=ROTATION_ACC_DEG_S2)


def sqrt_controller(error: float, gain: float, accel: float, dt: float) -> float:
    """ArduPilot's sqrt_controller for error >= 0: the rate that brings `error` to zero,
    gain * error near zero, sqrt(2 accel (error - accel / 2 gain^2)) beyond accel / gain^2,
    and at most error / dt (the step does not overshoot)."""
    linear = accel / (gain * gain)
    rate = math.sqrt(2.0 * accel * (error - 0.5 * linear)) if error > linear else gain * error
    return min(rate, error / dt) if dt > 0.0 else rate


def stop_distance(speed: float, gain: float, accel: float) -> float:
    """How far the shaper's braking goes from `speed` (>= 0) to rest, so that a target that
    far ahead is reached without overshoot: speed / gain in the linear region, the braking
    curve's speed^2 / 2 accel (plus half its linear distance) beyond it."""
    if speed <= accel / gain:
        return speed / gain
    return speed * speed / (2.0 * accel) + accel / (2.0 * gain * gain)


def stopping_pose(ref: Reference, lim: StickSettings) -> tuple[Vec3, Quat]:
    """Where a reference moving as `ref` comes to rest when braked within `lim` (HOLD's
    target: PX4 and ArduPilot brake, then hold where they stopped)."""
    p, v, w = ref.p_enu_m, ref.v_enu_m_s, ref.omega_flu_rad_s
    h = math.hypot(v[0], v[1])
    k = stop_distance(h, GAIN_1_S, lim.acc_xy_m_s2) / h if h > 0.0 else 0.0
    up = v[2] > 0.0  # braking a climb takes a downward acceleration
    dz = stop_distance(abs(v[2]), GAIN_1_S, lim.acc_down_m_s2 if up else lim.acc_up_m_s2)
    n = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    turn = stop_distance(n, GAIN_ATT_1_S, math.radians(lim.yaw_acc_deg_s2)) / n \
        if n > 0.0 else 0.0
    return ((p[0] + v[0] * k, p[1] + v[1] * k, p[2] + math.copysign(dz, v[2])),
            q_mul(ref.q_enu_flu, q_exp((w[0] * turn, w[1] * turn, w[2] * turn))))


def settled(s: Shaped) -> bool:
    """The reference is the sample's pose, still: no offset, no rate, no feed-forward."""
    return not any((*s.e_enu_m, *s.de_enu_m_s, *s.eps_rad, *s.deps_rad_s, *s.v_enu_m_s,
                    *s.a_enu_m_s2, *s.omega_flu_rad_s))


def start(t_us: int, ref: Reference) -> Shaped:
    """Entering OFFBOARD at `ref` (the reference flown so far, or the pose held): no sample
    yet, the reference continues from there without acceleration."""
    held = Reference(ref.p_enu_m, ref.q_enu_flu, ref.v_enu_m_s, _ZERO, ref.omega_flu_rad_s,
                     _ZERO)
    return Shaped(t_us, -1, t_us, ref.p_enu_m, ref.v_enu_m_s, _ZERO, ref.q_enu_flu,
                  ref.omega_flu_rad_s, _ZERO, _ZERO, _ZERO, _ZERO, held)


def _setpoint(s: Shaped, tau: float) -> tuple[Vec3, Vec3, Quat]:
    """The sample extrapolated by tau seconds: position, velocity, attitude."""
    p, v, a = s.p_enu_m, s.v_enu_m_s, s.a_enu_m_s2
    h = 0.5 * tau * tau
    w = s.omega_flu_rad_s
    return ((p[0] + v[0] * tau + a[0] * h, p[1] + v[1] * tau + a[1] * h,
             p[2] + v[2] * tau + a[2] * h),
            (v[0] + a[0] * tau, v[1] + a[1] * tau, v[2] + a[2] * tau),
            q_mul(s.q_enu_flu, q_exp((w[0] * tau, w[1] * tau, w[2] * tau))))


def right_jacobian(phi: Vec3, x: Vec3) -> Vec3:
    """J_r(phi) x: the body rate of exp(phi) when phi changes at x."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    if th2 < 1e-12:
        a, b = 0.5, 1.0 / 6.0
    else:
        th = math.sqrt(th2)
        a, b = (1.0 - math.cos(th)) / th2, (th - math.sin(th)) / (th2 * th)
    px = cross(phi, x)
    ppx = cross(phi, px)
    return (x[0] - a * px[0] + b * ppx[0], x[1] - a * px[1] + b * ppx[1],
            x[2] - a * px[2] + b * ppx[2])


def right_jacobian_inv(phi: Vec3, w: Vec3) -> Vec3:
    """J_r(phi)^-1 w: how phi changes for a body rate w of exp(phi); beyond 3 rad, where
    the inverse grows without bound towards pi, w itself."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    th = math.sqrt(th2)
    if th > 3.0:
        return w
    c = 1.0 / 12.0 if th < 1e-6 else \
        1.0 / th2 - (1.0 + math.cos(th)) / (2.0 * th * math.sin(th))
    pw = cross(phi, w)
    ppw = cross(phi, pw)
    return (w[0] + 0.5 * pw[0] + c * ppw[0], w[1] + 0.5 * pw[1] + c * ppw[1],
            w[2] + 0.5 * pw[2] + c * ppw[2])


def _anchor(s: Shaped, target: Target) -> Shaped:
    """Take a new sample at s.t_us, the offsets chosen so that the reference stays s.ref."""
    ref = s.ref
    p = target.p_enu_m if target.p_enu_m is not None else ref.p_enu_m
    q = target.q_enu_flu if target.q_enu_flu is not None else ref.q_enu_flu
    v, w = target.v_enu_m_s, target.omega_flu_rad_s
    e = (ref.p_enu_m[0] - p[0], ref.p_enu_m[1] - p[1], ref.p_enu_m[2] - p[2])
    de = (ref.v_enu_m_s[0] - v[0], ref.v_enu_m_s[1] - v[1], ref.v_enu_m_s[2] - v[2])
    q_e = q_mul(q_conj(q), ref.q_enu_flu)
    eps = q_log(q_e)
    w_seen = q_rotate_inv(q_e, w)
    deps = right_jacobian_inv(eps, (ref.omega_flu_rad_s[0] - w_seen[0],
                                    ref.omega_flu_rad_s[1] - w_seen[1],
                                    ref.omega_flu_rad_s[2] - w_seen[2]))
    return s._replace(seq=target.seq, anchor_us=s.t_us, p_enu_m=p, v_enu_m_s=v,
                      a_enu_m_s2=target.a_enu_m_s2, q_enu_flu=q, omega_flu_rad_s=w,
                      e_enu_m=e, de_enu_m_s=de, eps_rad=eps, deps_rad_s=deps)


Vec = tuple[float, ...]


def _decay(e: Vec, de: Vec, dt: float, speed: float, accel: float, gain: float
           ) -> tuple[Vec, Vec, Vec]:
    """One step of a vector offset toward zero: (offset, rate, rate's change per second)."""
    n = math.sqrt(sum(x * x for x in e))
    if n > 0.0:
        mag = min(sqrt_controller(n, gain, accel, dt), speed)
        want = tuple(-x / n * mag for x in e)
    else:
        want = tuple(0.0 for _ in e)
    dv = tuple(w - r for w, r in zip(want, de, strict=True))
    m = math.sqrt(sum(x * x for x in dv))
    if m > accel * dt:  # so m > 0
        dv = tuple(x * accel * dt / m for x in dv)
    rate = tuple(r + x for r, x in zip(de, dv, strict=True))
    new = tuple(x + r * dt for x, r in zip(e, rate, strict=True))
    change = tuple(x / dt for x in dv) if dt > 0.0 else tuple(0.0 for _ in e)
    return new, rate, change


def _decay_up(e: float, de: float, dt: float, lim: StickSettings) -> tuple[float, float, float]:
    """The vertical offset (ENU up): climbs at most speed_up, sinks at most speed_down; the
    rate changes by at most acc_up up and acc_down down per second."""
    if e > 0.0:  # above the set-point: sink, braking with an upward acceleration
        want = -min(sqrt_controller(e, GAIN_1_S, lim.acc_up_m_s2, dt), lim.speed_down_m_s)
    elif e < 0.0:
        want = min(sqrt_controller(-e, GAIN_1_S, lim.acc_down_m_s2, dt), lim.speed_up_m_s)
    else:
        want = 0.0
    dv = max(-lim.acc_down_m_s2 * dt, min(lim.acc_up_m_s2 * dt, want - de))
    rate = de + dv
    return e + rate * dt, rate, dv / dt if dt > 0.0 else 0.0


def advance(s: Shaped, t_us: int, target: Target | None, lim: StickSettings
            ) -> tuple[Shaped, Reference]:
    """The reference at t_us (flight clock): the offsets decay over the step, and a new
    sample (target.seq not s.seq) is then anchored where this reference is."""
    dt = min(max((t_us - s.t_us) * 1e-6, 0.0), MAX_DT_S)
    ex, dex, ddex = _decay(s.e_enu_m[:2], s.de_enu_m_s[:2], dt, lim.speed_xy_m_s,
                           lim.acc_xy_m_s2, GAIN_1_S)
    ez, dez, ddez = _decay_up(s.e_enu_m[2], s.de_enu_m_s[2], dt, lim)
    eps, deps, ddeps = _decay(s.eps_rad, s.deps_rad_s, dt, math.radians(lim.yaw_rate_deg_s),
                              math.radians(lim.yaw_acc_deg_s2), GAIN_ATT_1_S)
    e: Vec3 = (ex[0], ex[1], ez)
    de: Vec3 = (dex[0], dex[1], dez)
    e_v: Vec3 = (eps[0], eps[1], eps[2])
    de_v: Vec3 = (deps[0], deps[1], deps[2])
    if max(map(abs, (*e, *de))) < SETTLED:
        e = de = _ZERO
    if max(map(abs, (*e_v, *de_v))) < SETTLED:
        e_v = de_v = _ZERO
    tau = (t_us - s.anchor_us) * 1e-6
    p_sp, v_sp, q_sp = _setpoint(s, tau)
    q_e = q_exp(e_v)
    w_seen = q_rotate_inv(q_e, s.omega_flu_rad_s)
    w_e = right_jacobian(e_v, de_v)
    dw_e = right_jacobian(e_v, (ddeps[0], ddeps[1], ddeps[2]))
    a = s.a_enu_m_s2
    ref = Reference((p_sp[0] + e[0], p_sp[1] + e[1], p_sp[2] + e[2]), q_mul(q_sp, q_e),
                    (v_sp[0] + de[0], v_sp[1] + de[1], v_sp[2] + de[2]),
                    (a[0] + ddex[0], a[1] + ddex[1], a[2] + ddez),
                    (w_seen[0] + w_e[0], w_seen[1] + w_e[1], w_seen[2] + w_e[2]), dw_e)
    s = s._replace(t_us=t_us, e_enu_m=e, de_enu_m_s=de, eps_rad=e_v, deps_rad_s=de_v, ref=ref)
    if target is not None and target.seq != s.seq:
        s = _anchor(s, target)
    return s, ref
