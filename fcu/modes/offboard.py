"""OFFBOARD: the streamed set-point made into a reference the vehicle can fly; pure, no I/O.

SET_POSITION_TARGET_LOCAL_NED and SET_ATTITUDE_TARGET give a target pose, each part
optional, with optional velocity, acceleration and body-rate feed-forward, a few tens of
times a second. A sample holds from the control step at which it is first seen (its
"anchor"), extrapolated with its own feed-forward over the flight time tau since then:

    p_sp(tau) = p + v tau + a tau^2 / 2        q_sp(tau) = q (x) exp(omega tau)

A part the sample does not give is anchored where the reference is (velocity-only samples
fly the velocity; no attitude and no yaw keeps the attitude). The reference is the target
plus an offset (`fcu.reference.approach`):

    p_ref = p_sp + e                           q_ref = q_sp (x) exp(eps)

When a sample is first seen, e and eps (with their rates and accelerations) take the values
that keep the reference continuous in pose, velocity, acceleration, body rate and its
derivative; then they go to zero along the quintic of the shortest duration that keeps the
correction within the approach limits of `StickSettings` (POSCTL's MPC_VEL_MANUAL,
MPC_Z_VEL_MAX_UP / _DN, MPC_ACC_HOR, MPC_ACC_UP_MAX / _DOWN_MAX, and a rotation about any
axis at `ROTATION_RATE_DEG_S` and `ROTATION_ACC_DEG_S2`: `limits`) and what the allocation
commands along the whole reference within every actuator's envelope (rotor speed with its
lag, tilt-servo rate: `fcu.envelope.feasibility`), for rotations about any axis.

A sample that continues the trajectory of the one before (the same set-point, extrapolated,
in every part it gives) keeps the approach under way; so a stream that is a flyable
trajectory (velocity and acceleration consistent with its positions) is flown as streamed
(the offset stays zero), and a step of any size is flown within the limits. Taken as a step
of the tracker's error instead, a 10 m, 150 deg step saturated the rotors for seconds and put
the vehicle on the ground.

A sample whose attitude can only be reached with a tilt flipping half a turn, or with one
turning faster than its servo however slowly the approach goes (up to `approach.D_MAX_S`),
(a rotor's thrust passing through zero on the way, `approach.flip`: a large roll about the
body's forward axis on both presets) is not flown in attitude: the attitude flown is braked
and held, the rest of the sample flown, and `Shaped.refused` says why (the commander sends
it as a STATUSTEXT warning). Flown, such a roll rate-limits tilt servos 2 and 5 while they
turn half a revolution; stretched, it lost the vehicle.

HOLD brakes a moving reference with the same approach, its end free (`stop`): the vehicle
holds where the braking ends.

A new sample is seen at the step whose reference has just been computed from the one
before, and is anchored there: it shapes the reference from the next step on.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

from common.outcome import ATTITUDE_NOT_FLOWN
from fcu.control.dualquat import Quat, Vec3, q_angle, q_conj, q_exp, q_log, q_mul, q_rotate_inv
from fcu.envelope.excess import TILT
from fcu.envelope.feasibility import Envelope
from fcu.modes.manual import StickSettings
from fcu.reference import approach
from fcu.reference.approach import Approach, Offset, Setpoint
from fcu.reference.approach_kernels import offset_rate, reference_kernel
from fcu.stages import Reference

ROTATION_RATE_DEG_S = 90.0  # a rotation's approach rate, about any axis
ROTATION_ACC_DEG_S2 = 180.0
# A sample within this (m, m/s, m/s^2) of the set-point before continues it, and within this
# (rad, rad/s): above the float32 rounding of MAVLink's fields (3.8e-6 m at 100 m), so a
# stream re-sent through the wire does not re-plan at every sample.
SAME_M = 2e-5
SAME_RAD = 2e-5
COAST = -2  # Shaped.seq of a coast (`coast`): no sample, no plan yet
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
    """The shaper's state at t_us: the sample in force (seq, its anchor time and set-point),
    the approach under way (None: none) and when it began, and the reference it gave."""

    t_us: int
    seq: int
    anchor_us: int
    sp: Setpoint
    plan: Approach | None
    plan_us: int
    ref: Reference
    refused: str = ""  # why the sample's attitude is not flown ("": it is)
    asked: Target | None = None  # the sample whose attitude was refused


def limits(sticks: StickSettings) -> StickSettings:
    """POSCTL's speeds and accelerations with the rotation limits of OFFBOARD's approach
    (not the yaw stick's MPC_MAN_Y_MAX, which may be 0)."""
    return replace(sticks, yaw_rate_deg_s=ROTATION_RATE_DEG_S,
                   yaw_acc_deg_s2=ROTATION_ACC_DEG_S2)


def _extrapolated(sp: Setpoint, tau: float) -> Setpoint:
    """The set-point tau seconds after its anchor."""
    p, v, a, w = sp.p, sp.v, sp.a, sp.w
    h = 0.5 * tau * tau
    return Setpoint((p[0] + v[0] * tau + a[0] * h, p[1] + v[1] * tau + a[1] * h,
                     p[2] + v[2] * tau + a[2] * h),
                    (v[0] + a[0] * tau, v[1] + a[1] * tau, v[2] + a[2] * tau), a,
                    q_mul(sp.q, q_exp((w[0] * tau, w[1] * tau, w[2] * tau))), w)


def _offset(ref: Reference, sp: Setpoint) -> Offset:
    """The offset (and its rates) that makes set-point sp plus it equal `ref`."""
    e = (ref.p_enu_m[0] - sp.p[0], ref.p_enu_m[1] - sp.p[1], ref.p_enu_m[2] - sp.p[2])
    de = (ref.v_enu_m_s[0] - sp.v[0], ref.v_enu_m_s[1] - sp.v[1], ref.v_enu_m_s[2] - sp.v[2])
    dde = (ref.a_enu_m_s2[0] - sp.a[0], ref.a_enu_m_s2[1] - sp.a[1],
           ref.a_enu_m_s2[2] - sp.a[2])
    q_e = q_mul(q_conj(sp.q), ref.q_enu_flu)
    eps = q_log(q_e)
    w_seen = q_rotate_inv(q_e, sp.w)
    deps = offset_rate(eps, (ref.omega_flu_rad_s[0] - w_seen[0],
                                    ref.omega_flu_rad_s[1] - w_seen[1],
                                    ref.omega_flu_rad_s[2] - w_seen[2]))
    ddeps = offset_rate(eps, ref.omega_dot_flu_rad_s2)
    return Offset(e, de, dde, eps, deps, ddeps)


def _reference(s: Shaped, t_us: int) -> Reference:
    sp, plan = s.sp, s.plan
    tau_sp = (t_us - s.anchor_us) * 1e-6
    if plan is None:
        x = _extrapolated(sp, tau_sp)
        return Reference(x.p, x.q, x.v, sp.a, sp.w, _ZERO)
    p, q, v, a, w, wd = reference_kernel(*approach.floats(sp), plan.coeffs,
                                                  plan.duration_s, tau_sp,
                                                  (t_us - s.plan_us) * 1e-6)
    return Reference(p, q, v, a, w, wd)


def settled(s: Shaped) -> bool:
    """The reference is the sample's pose, still: no approach under way, no feed-forward."""
    done = s.plan is None or (s.t_us - s.plan_us) * 1e-6 >= s.plan.duration_s
    return done and not any((*s.sp.v, *s.sp.a, *s.sp.w))


def moving(ref: Reference) -> bool:
    """`ref` has a velocity, acceleration, body rate or its derivative: starting or braking
    from it needs a plan (from a still reference it is none, `approach.plan`)."""
    return any((*ref.v_enu_m_s, *ref.a_enu_m_s2, *ref.omega_flu_rad_s,
                *ref.omega_dot_flu_rad_s2))


def coast(t_us: int, ref: Reference) -> Shaped:
    """`ref` extrapolated at its velocity, acceleration and body rate (seq COAST, no plan):
    what flies for the moments a start or a brake is planned beside the control loop
    (`start_ahead`, `brake_ahead`), continuous in pose, velocity, acceleration and rate."""
    sp = Setpoint(ref.p_enu_m, ref.v_enu_m_s, ref.a_enu_m_s2, ref.q_enu_flu,
                  ref.omega_flu_rad_s)
    return Shaped(t_us, COAST, t_us, sp, None, t_us, ref)


def start_ahead(s: Shaped, t_us: int, lim: StickSettings, env: Envelope | None = None
                ) -> tuple[Shaped, Reference]:
    """OFFBOARD's start (`start`) planned at t_us, ahead, from where `s` is then; (the
    shaper, that reference). A job beside the loop (`fcu.work`)."""
    ref = _reference(s, t_us)
    return start(t_us, ref, lim, env), ref


def brake_ahead(s: Shaped, t_us: int, lim: StickSettings, env: Envelope | None = None
                ) -> tuple[Shaped, Reference]:
    """HOLD's brake (`brake`) planned at t_us, ahead, from where `s` is then; (the shaper,
    the pose held). A job beside the loop (`fcu.work`)."""
    return brake(t_us, _reference(s, t_us), lim, env)


def start(t_us: int, ref: Reference, lim: StickSettings, env: Envelope | None = None
          ) -> Shaped:
    """Entering OFFBOARD at `ref` (the reference flown so far, or the pose held): no sample
    yet, the reference continues from there at its velocity and body rate, its acceleration
    and the rate's derivative brought to zero within the envelope."""
    sp = Setpoint(ref.p_enu_m, ref.v_enu_m_s, _ZERO, ref.q_enu_flu, ref.omega_flu_rad_s)
    plan = approach.plan(env, lim, sp, _offset(ref, sp))
    return Shaped(t_us, -1, t_us, sp, plan, t_us, ref)


def _shifted(sp: Setpoint, ref: Reference, plan: Approach | None) -> Setpoint:
    """The set-point whose offset from `ref` is where `plan` starts (a free end moves it)."""
    if plan is None:
        return sp
    e, eps = approach.start_offset(plan)
    return sp._replace(p=(ref.p_enu_m[0] - e[0], ref.p_enu_m[1] - e[1], ref.p_enu_m[2] - e[2]),
                       q=q_mul(ref.q_enu_flu, q_exp((-eps[0], -eps[1], -eps[2]))))


def brake(t_us: int, ref: Reference, lim: StickSettings, env: Envelope | None = None
          ) -> tuple[Shaped, Reference]:
    """HOLD from `ref`: it brakes within the limits and the envelope, and holds where it
    comes to rest; (the shaper, the pose held)."""
    rest = Setpoint(ref.p_enu_m, _ZERO, _ZERO, ref.q_enu_flu, _ZERO)
    plan = approach.plan(env, lim, rest, _offset(ref, rest), free=(True, True))
    held = _shifted(rest, ref, plan)
    return Shaped(t_us, 0, t_us, held, plan, t_us, ref), \
        Reference(held.p, held.q, _ZERO, _ZERO, _ZERO, _ZERO)


def _continues(s: Shaped, target: Target, t_us: int) -> bool:
    """`target` is the set-point in force, extrapolated to t_us, in every part it gives."""
    now = _extrapolated(s.sp, (t_us - s.anchor_us) * 1e-6)
    close = max(abs(x - y) for x, y in zip((*now.v, *now.a), (*target.v_enu_m_s,
                                                             *target.a_enu_m_s2),
                                           strict=True)) < SAME_M and \
        max(abs(x - y) for x, y in zip(now.w, target.omega_flu_rad_s, strict=True)) < SAME_RAD
    if target.p_enu_m is not None:
        close = close and math.dist(now.p, target.p_enu_m) < SAME_M
    if target.q_enu_flu is not None:
        close = close and q_angle(q_mul(q_conj(now.q), target.q_enu_flu)) < SAME_RAD
    return close


def _anchor(s: Shaped, target: Target, lim: StickSettings, env: Envelope | None) -> Shaped:
    """Take a new sample at s.t_us: the approach planned from the reference s.ref."""
    if s.seq >= 0 and (_continues(s, target, s.t_us) or
                       (s.asked is not None and target._replace(seq=0) == s.asked)):
        return s._replace(seq=target.seq)
    ref = s.ref
    sp = Setpoint(target.p_enu_m if target.p_enu_m is not None else ref.p_enu_m,
                  target.v_enu_m_s, target.a_enu_m_s2,
                  target.q_enu_flu if target.q_enu_flu is not None else ref.q_enu_flu,
                  target.omega_flu_rad_s)
    free = (target.p_enu_m is None, target.q_enu_flu is None)
    plan = approach.plan(env, lim, sp, _offset(ref, sp), free)
    refused, asked = "", None
    if plan is not None and not plan.fits and plan.excess is not None and \
            plan.excess.kind in (approach.FLIP, TILT):
        # the attitude cannot be reached along its geodesic in any time the planner tries:
        # hold the one flown (braked), fly the rest (STATUSTEXT's 50 characters)
        held_sp = sp._replace(q=ref.q_enu_flu, w=_ZERO)
        held_free = (free[0], True)
        held = approach.plan(env, lim, held_sp, _offset(ref, held_sp), held_free)
        if held is None or held.fits or plan.excess.kind == approach.FLIP:
            # the attitude is what does not fit (holding it, the rest does, or a flip)
            n = plan.excess.number
            refused = f"{ATTITUDE_NOT_FLOWN}: tilt servo {n} would flip" \
                if plan.excess.kind == approach.FLIP else \
                f"{ATTITUDE_NOT_FLOWN}: tilt servo {n} needs {plan.excess.need:.1f} rad/s"
            asked = target._replace(seq=0)
            sp, free, plan = held_sp, held_free, held
    return s._replace(seq=target.seq, anchor_us=s.t_us, sp=_shifted(sp, ref, plan)
                      if any(free) else sp, plan=plan, plan_us=s.t_us, refused=refused,
                      asked=asked)


def advance(s: Shaped, t_us: int, target: Target | None, lim: StickSettings,
            env: Envelope | None = None) -> tuple[Shaped, Reference]:
    """The reference at t_us (flight clock), and a new sample (target.seq not s.seq) then
    anchored where this reference is."""
    ref = _reference(s, t_us)
    s = s._replace(t_us=t_us, ref=ref)
    if target is not None and target.seq != s.seq:
        s = _anchor(s, target, lim, env)
    return s, ref
