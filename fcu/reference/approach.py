"""An approach planned to fit every actuator: the offset between a reference and the set-point
it joins, brought to zero smoothly in the shortest duration the vehicle flies (pure).

OFFBOARD and HOLD (`fcu.modes.offboard`) fly a set-point (p, v, a, q, omega: a pose with its
feed-forward, extrapolated from its anchor) plus an offset that keeps the reference continuous
where the set-point jumps:

    p_ref = p_sp + e                           q_ref = q_sp (x) exp(eps)

e in ENU, eps a rotation vector in the set-point's body frame (FLU). Each of their six
components x goes from its value, rate and acceleration when the plan starts to rest at zero
in D seconds as x0 (1 - B(t / D)) plus the quintic that takes its starting rate and
acceleration to rest from zero (`fcu.reference.approach_kernels`). On a long approach
with a fixed end the starting rates are braked on their own instead, with a free end, in
twice the shortest time that fits the limits, or in that time where the longer brake
leaves them (`RatesBrakes`), and the blend takes the rest of the offset: taken to rest
over the whole approach, the quintic's excursion grows as v0 D and a0 D^2, and no
duration fitted. B is `blend`: the
minimum-jerk 10 s^3 - 15 s^4 + 6 s^5, or, on a long step, a cruise between minimum-jerk
ramps of share r (`cruise_share`: the ramps reach the speed limit at the acceleration
limit); both are tried and the shorter kept. Position, velocity and acceleration are then
continuous at both ends, so the accelerations the wrench follows never step (a step in them
is a step in the tilt angles, which a rate-limited servo cannot take: the shaper without a
jerk limit that this replaced rate-limited tilt servos for 0.9 s and more on a 170 deg roll).

The reference's body rate is exp(eps)^-1 omega_sp exp(eps) + J_r(eps) d eps/dt (J_r: the
right Jacobian of SO(3)'s exponential), its derivative taken as J_r(eps) d^2 eps/dt^2 (exact
while eps keeps its direction, as it does from rest).

D is the shortest duration found (`plan`) for which
* the offset's rates stay within the approach limits (`StickSettings`: horizontal speed and
  acceleration, climb and descent speeds, the up and down accelerations, and a rotation rate
  and acceleration about any axis), and
* what the allocation commands along the whole reference (set-point plus offset) fits every
  actuator of `fcu.envelope.feasibility.Envelope`: rotor speed with its lag and slowing, tilt-servo
  rate (the kernels the mission check uses, on the samples' exact central differences in
  time). Without an envelope (no vehicle), the limits alone.

A rotation along which a rotor's thrust passes through zero makes its tilt flip by half a
revolution at any duration (`flip`): no duration fits, and a slower one leaves that rotor's
thrust misdirected for longer while its servo turns (a 170 deg roll stretched to 11 s lost the
vehicle there); such an approach is flown at the limits' bound, `fits` False, its excess the
flip (kind FLIP).

Durations are tried from the limits' rest-to-rest bound up, each failing one by a ratio r
multiplied by max(GROW_MIN, min(sqrt r, GROW_MAX)), then bisected to REFINE_TOL. None fitting
up to D_MAX_S: the longest is flown and `Approach.fits` is False.

An approach with a free end (HOLD: the reference brakes and holds where it comes to rest; a
sample without a position or an attitude: that part is not a target) makes the offset's
start depend on D: for a rate v0 and acceleration a0 it starts at -(v0 D / 2 + a0 D^2 / 12),
the end of the cubic rate profile from (v0, a0) to rest, and the set-point moves by as much.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.warm_ups import warm_up
from fcu.control.dualquat import Quat, Vec3
from fcu.envelope.excess import KINDS, Excess, excess_kernel
from fcu.envelope.feasibility import TILT_STEP_S, Envelope, _nominal_wrench_rows
from fcu.modes.manual import StickSettings
from fcu.reference.approach_kernels import (
    kinematic_ratios,
    offset_kernel,
    offset_rate,
    quintic_to_rest,
    reference_kernel,
    reference_rows,
)
from fcu.reference.trajectory import QUINTIC_PEAK_RATE

D_MIN_S = 0.02  # the shortest approach
D_MAX_S = 120.0  # the longest tried
GROW_MIN = 1.05
GROW_MAX = 4.0
REFINE_TOL = 0.02  # relative: the duration found is at most this much too long
MAX_TRIES = 80
SAMPLES = 64  # at least this many instants of the approach are checked
STEP_RAD = 0.01  # ... at most this much attitude turned between two of them
SAMPLES_MAX = 2048
RAMP_SAMPLES = 32
DIFF_S = 1e-5  # the central differences' time step (s)
TINY = 1e-9  # an offset and its rates below this are zero: no plan
CRUISE_MAX = 0.4  # a longer ramp share flies as the plain minimum-jerk blend
RATES_HEADROOM = 2.0  # the starting rates' quintic lasts this many times its shortest
GROW_RATES = 1.25  # ... found growing by this factor
RATES_SLACK = 1.1  # a limit the rates' brake overshoots at any duration: this times its least
FLIP_RAD = 1.0  # a nominal tilt that turns this much between two samples flips (`flip`)
FLIP = "tilt flip"


class Offset(NamedTuple):
    """An offset's value, rate and acceleration: e (ENU) and eps (FLU rotation vector)."""

    e: Vec3
    de: Vec3
    dde: Vec3
    eps: Vec3
    deps: Vec3
    ddeps: Vec3


class Setpoint(NamedTuple):
    """The set-point at its anchor (ENU / FLU), extrapolated with its own feed-forward."""

    p: Vec3
    v: Vec3
    a: Vec3
    q: Quat
    w: Vec3


class Approach(NamedTuple):
    """A planned approach: the quintics' coefficients (6 components x 6, in s = tau / D),
    its duration, and the most demanding actuator along it (None: no envelope checked)."""

    coeffs: np.ndarray  # (6, 7): `coefficients`
    duration_s: float
    fits: bool
    excess: Excess | None


ZERO: Vec3 = (0.0, 0.0, 0.0)



def _limits(lim: StickSettings, x: Offset) -> np.ndarray:
    """The limits of `kinematic_ratio`, each at least what the offset starts with (a
    reference that enters faster than a limit, say HOLD at 10 m/s, slows from there)."""
    return np.array([max(lim.speed_xy_m_s, math.hypot(x.de[0], x.de[1])),
                     max(lim.speed_up_m_s, x.de[2]), max(lim.speed_down_m_s, -x.de[2]),
                     max(lim.acc_xy_m_s2, math.hypot(x.dde[0], x.dde[1])),
                     max(lim.acc_up_m_s2, x.dde[2]), max(lim.acc_down_m_s2, -x.dde[2]),
                     max(math.radians(lim.yaw_rate_deg_s), _norm(x.deps)),
                     max(math.radians(lim.yaw_acc_deg_s2), _norm(x.ddeps))])


def _f3(v: Vec3) -> Vec3:
    return float(v[0]), float(v[1]), float(v[2])


def floats(sp: Setpoint) -> tuple[Vec3, Vec3, Vec3, Quat, Vec3]:
    """The set-point's parts as floats (the kernels are compiled for floats only)."""
    q = sp.q
    return (_f3(sp.p), _f3(sp.v), _f3(sp.a), (float(q[0]), float(q[1]), float(q[2]),
                                              float(q[3])), _f3(sp.w))


def _norm(x: Vec3) -> float:
    return math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])


def free_end(x: Offset, d: float, free: tuple[bool, bool] = (True, True)) -> Offset:
    """The offset of an approach whose end is free in position (free[0]) or attitude
    (free[1]): it starts where the rates' cubic profile to rest ends, -(v0 d / 2 +
    a0 d^2 / 12) (module docstring)."""
    def start(v0: Vec3, a0: Vec3) -> Vec3:
        return (-(v0[0] * d / 2.0 + a0[0] * d * d / 12.0),
                -(v0[1] * d / 2.0 + a0[1] * d * d / 12.0),
                -(v0[2] * d / 2.0 + a0[2] * d * d / 12.0))
    return x._replace(e=start(x.de, x.dde) if free[0] else x.e,
                      eps=start(x.deps, x.ddeps) if free[1] else x.eps)


def coefficients(x: Offset, d: float, r: float = 0.0,
                 rho: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Per component (e, then eps): its start, the quintic of its start's rates (from 0)
    over rho * d (rho[0] for e, rho[1] for eps), the cruise share r, rho, and where the
    rates' brake starts when rho < 1 (`approach_kernels._component`)."""
    dp, dq = rho[0] * d, rho[1] * d
    stop_e = free_end(x, dp, (True, False)).e if rho[0] < 1.0 else ZERO
    stop_eps = free_end(x, dq, (False, True)).eps if rho[1] < 1.0 else ZERO
    rows = [(x.e[j], *quintic_to_rest(0.0, x.de[j], x.dde[j], dp)[1:], r, rho[0], stop_e[j])
            for j in range(3)] + \
        [(x.eps[j], *quintic_to_rest(0.0, x.deps[j], x.ddeps[j], dq)[1:], r, rho[1],
          stop_eps[j]) for j in range(3)]
    return np.array(rows)


def at_rest(x: Offset) -> bool:
    return max(map(abs, (*x.e, *x.de, *x.dde, *x.eps, *x.deps, *x.ddeps))) < TINY


def _components(x: Offset, lim: StickSettings) -> list[tuple[float, float, float]]:
    """(distance, speed limit, acceleration limit) of the offset's horizontal, vertical
    (a reference below its set-point climbs) and rotation parts."""
    return [(math.hypot(x.e[0], x.e[1]), lim.speed_xy_m_s, lim.acc_xy_m_s2),
            (abs(x.e[2]), lim.speed_up_m_s if x.e[2] < 0.0 else lim.speed_down_m_s,
             min(lim.acc_up_m_s2, lim.acc_down_m_s2)),
            (_norm(x.eps), math.radians(lim.yaw_rate_deg_s), math.radians(lim.yaw_acc_deg_s2))]


def _bound(x: Offset, lim: StickSettings, r: float = 0.0) -> float:
    """A lower bound on D from the limits (the search starts there and never goes below).
    From rest, `blend`'s top rate is 1.875 (r = 0) or 1 / (1 - r) times the mean, its top
    acceleration 5.774 or 1.875 / (r (1 - r)) times the distance / D^2; a rate v0 brakes at
    most at the limit."""
    d = D_MIN_S
    for dist, speed, acc in _components(x, lim):
        if r <= 0.0:
            d = max(d, QUINTIC_PEAK_RATE * dist / speed, math.sqrt(5.774 * dist / acc))
        else:
            d = max(d, dist / (speed * (1.0 - r)), math.sqrt(1.875 * dist / (acc * r * (1 - r))))
    return max(d, math.hypot(x.de[0], x.de[1]) / lim.acc_xy_m_s2,
               abs(x.de[2]) / min(lim.acc_up_m_s2, lim.acc_down_m_s2),
               _norm(x.deps) / math.radians(lim.yaw_acc_deg_s2))


def cruise_share(x: Offset, lim: StickSettings) -> float:
    """The cruise share r (`blend`) that reaches the speed limit of the part that takes
    longest, ramping at its acceleration limit: D = dist / V + 1.875 V / A, r = 1.875 V /
    (A D); 0 (no cruise) where the ramps would take most of it (r > CRUISE_MAX)."""
    best_d, r = 0.0, 0.0
    for dist, speed, acc in _components(x, lim):
        ramp = QUINTIC_PEAK_RATE * speed / acc
        d = dist / speed + ramp
        if dist > 0.0 and d > best_d:
            best_d, r = d, ramp / d
    return r if 0.0 < r <= CRUISE_MAX else 0.0


def _instants(sp: Setpoint, x: Offset, d: float, r: float = 0.0) -> np.ndarray:
    """Check instants: evenly spaced over [0, d], at most STEP_RAD of attitude apart (the
    blend's top rate is at most twice its mean), and RAMP_SAMPLES in each ramp of a
    cruise."""
    turn = 2.0 * _norm(x.eps) + _norm(sp.w) * d + _norm(x.deps) * d
    n = max(SAMPLES, math.ceil(turn / STEP_RAD) + 1, math.ceil(RAMP_SAMPLES / r) if r else 0)
    return np.linspace(0.0, d, int(min(SAMPLES_MAX, n)))


def _allocated(env: Envelope, sp: Setpoint, k: np.ndarray, d: float, taus: np.ndarray
               ) -> np.ndarray:
    """Omega = A^+ [f_b; tau_b] of the nominal wrench along the reference at each tau
    (samples x 2n, contiguous)."""
    qs, acc, rate, rate_dot = reference_rows(*floats(sp), k, d, taus)
    v = env.vehicle
    wrench = _nominal_wrench_rows(v.mass_kg, v.gravity_m_s2, v.inertia_diag_kg_m2, qs, acc,
                                  rate, rate_dot)
    return np.ascontiguousarray(wrench.T @ env.pinv_t)


def kinematic_shares(lim: StickSettings, sp: Setpoint, x: Offset, d: float, r: float = 0.0,
                     rho: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """The largest share of each approach limit (`_limits`, in `kinematic_ratios`' order)
    the approach of offset x to set-point sp in d seconds uses."""
    k = coefficients(x, d, r, rho)
    return kinematic_ratios(k, d, _instants(sp, x, d, r), _limits(lim, x))


def check(env: Envelope | None, lim: StickSettings, sp: Setpoint, x: Offset, d: float,
          r: float = 0.0, rho: tuple[float, float] = (1.0, 1.0),
          allowed: tuple[float, ...] | None = None) -> tuple[float, Excess | None]:
    """(ratio, excess) of the approach of offset x to set-point sp in d seconds (its rates'
    quintic over rho * d): the largest share of a limit (`allowed[i]` times limit i, in
    `kinematic_ratios`' order) or an actuator's envelope it uses (> 1: it does not fit)."""
    k = coefficients(x, d, r, rho)
    taus = _instants(sp, x, d, r)
    shares = kinematic_ratios(k, d, taus, _limits(lim, x))
    ratio = float((shares if allowed is None else shares / np.array(allowed)).max())
    if env is None:
        return ratio, None
    n = len(taus)
    all_taus = np.concatenate([taus, taus - DIFF_S, taus + DIFF_S])
    om = _allocated(env, sp, k, d, all_taus)
    om0 = np.ascontiguousarray(om[:n])
    dom = np.ascontiguousarray((om[2 * n:] - om[n:2 * n]) / (2.0 * DIFF_S))
    zero = np.zeros_like(om0)
    r, kind, rotor, sample, need, limit = excess_kernel(
        om0, zero, dom, zero, np.zeros(n, dtype=np.bool_), 1.0, env.limit, env.tau_up,
        env.tau_down, env.tilt_limit, env.tilt_rate_max * TILT_STEP_S)
    return max(ratio, r), Excess(r, KINDS[kind], rotor + 1, need, limit, sample)


def flip(env: Envelope, sp: Setpoint, x: Offset, d: float) -> Excess | None:
    """A tilt that must turn half a revolution at once along the approach: where a rotor's
    thrust passes through zero (its lateral and vertical parts both), the nominal tilt jumps
    by pi between two samples, at any duration; None when there is none."""
    k = coefficients(x, d)
    taus = _instants(sp, x, d)
    om = _allocated(env, sp, k, d, taus)
    tilt = np.arctan2(om[:, 0::2], om[:, 1::2])
    step = np.abs(np.angle(np.exp(1j * np.diff(tilt, axis=0))))
    if not step.size or float(step.max()) < FLIP_RAD:
        return None
    sample, rotor = np.unravel_index(int(np.argmax(step)), step.shape)
    return Excess(math.inf, FLIP, int(rotor) + 1, float(step[sample, rotor]), FLIP_RAD,
                  int(sample))


def plan(env: Envelope | None, lim: StickSettings, sp: Setpoint, x: Offset,
         free: tuple[bool, bool] = (False, False)) -> Approach | None:
    """The shortest approach of offset x to set-point sp that fits (module docstring); where
    `free` (position, attitude), x's value there is free (`free_end`): the approach starts
    at the returned coefficients' first column. A fixed end is also tried with a cruise
    (`cruise_share`), the shorter kept. None: x is at rest at zero already."""
    if at_rest(free_end(x, 0.0, free)):
        return None
    d = _bound(free_end(x, 0.0, free), lim)  # a free part's value is no bound
    if free[0]:  # the free end's top rate is its start's; its acceleration 1.5 v0 / d
        d = max(d, 1.5 * math.hypot(x.de[0], x.de[1]) / lim.acc_xy_m_s2,
                1.5 * abs(x.de[2]) / min(lim.acc_up_m_s2, lim.acc_down_m_s2))
    if free[1]:
        d = max(d, 1.5 * _norm(x.deps) / math.radians(lim.yaw_acc_deg_s2))
    if env is not None:
        flipped = flip(env, sp, free_end(x, d, free), d)
        if flipped is not None:  # slower would leave that rotor's thrust wrong for longer
            return Approach(coefficients(free_end(x, d, free), d), d, False, flipped)
    brakes = None if all(free) else RatesBrakes(lim, sp, x)
    best = _search(env, lim, sp, x, free, 0.0, d, brakes)
    r = 0.0 if any(free) else cruise_share(x, lim)
    if r > 0.0:
        cruise = _search(env, lim, sp, x, free, r, _bound(x, lim, r), brakes)
        if cruise.fits and (not best.fits or cruise.duration_s < best.duration_s):
            best = cruise
    return best


def _slack(shares: np.ndarray) -> tuple[float, ...]:
    """RATES_SLACK times each share of a limit the rates' brake uses where it overshoots
    that limit (the blend beside it needs room), 1 elsewhere: the others stay whole."""
    return tuple(float(RATES_SLACK * v) if v > 1.0 else 1.0 for v in shares)


class RatesBrakes:
    """How a fixed end's approach brakes the offset's starting rates on their own (a brake
    with a free end, the blend taking the rest of the offset), by the approach's duration
    (`at`). With d1 the shortest duration in which the brake alone stays within the limits
    (`shortest_s`): none up to RATES_HEADROOM d1 (the rates' quintic over the whole
    approach), RATES_HEADROOM d1 beyond; where that longer brake alone leaves the limits (a
    start accelerating towards a speed limit overshoots it more the longer it brakes: the
    blend beside it may offset that on a short approach, never on a long one), d1 itself
    from RATES_HEADROOM^2 d1 on (checked only when an approach that long is tried). Where
    no duration fits, the one where it overshoots least (`least`), the limits it overshoots
    slackened (`_slack`). A free end's part is its own brake (its rho stays 1): there only
    that slack counts, and HOLD's brake from a reference at or past a limit and still
    speeding up (a mission flies at its own speeds) takes a few seconds; it took 120 s and
    ran away at up to 32 m/s.

    Taken to rest over the whole of a long approach instead, the rates' quintic went out
    and came back by as much as v0 D and a0 D^2: an OFFBOARD set-point 39 m away taken
    while the reference still decelerated found no duration that fitted, and the longest
    tried ran the reference into the ground. With RATES_HEADROOM d1 alone, the same
    set-point taken while the body still turned faster towards the rotation limit found
    none either: the longest tried, 120 s, was flown."""

    def __init__(self, lim: StickSettings, sp: Setpoint, x: Offset) -> None:
        self._lim, self._sp = lim, sp
        self._rates = rates = x._replace(e=ZERO, eps=ZERO)
        self.shortest_s = 0.0  # d1; 0: no rates, or no duration fits (`least`)
        self.least: tuple[float, tuple[float, ...]] | None = None  # (duration, allowed)
        self._longer_fits: bool | None = None  # RATES_HEADROOM d1 within the limits
        if at_rest(rates):
            return
        d = _bound(rates, lim)
        least = (math.inf, d, np.zeros(8))
        for _ in range(MAX_TRIES):
            now = self._shares(d)
            ratio = float(now.max())
            if ratio <= 1.0:
                self.shortest_s = d
                return
            if ratio < least[0]:
                least = (ratio, d, now)
            elif d > 2.0 * least[1] or d >= D_MAX_S:  # past its least: it only grows now
                break
            d = min(D_MAX_S, d * GROW_RATES)
        self.least = (least[1], _slack(least[2]))

    def _shares(self, dur: float) -> np.ndarray:
        return kinematic_shares(self._lim, self._sp, free_end(self._rates, dur), dur)

    def at(self, dur: float) -> tuple[float, tuple[float, ...] | None]:
        """For an approach of dur seconds: (the share of it the brake lasts, 1: no brake;
        the limits' allowances, None: 1 each)."""
        if self.least is not None:
            return min(1.0, self.least[0] / dur), self.least[1]
        d1 = self.shortest_s
        longer = RATES_HEADROOM * d1
        if d1 == 0.0 or dur <= longer:
            return 1.0, None
        if dur > RATES_HEADROOM * longer:
            if self._longer_fits is None:
                self._longer_fits = float(self._shares(longer).max()) <= 1.0
            if not self._longer_fits:
                return d1 / dur, None
        return longer / dur, None


def _search(env: Envelope | None, lim: StickSettings, sp: Setpoint, x: Offset,
            free: tuple[bool, bool], r: float, d: float,
            brakes: RatesBrakes | None) -> Approach:
    """The shortest duration from d up that fits with cruise share r (module docstring);
    `brakes` None: made when a duration first fails (both ends free: only their slack
    counts, and it changes nothing where the brake fits)."""
    made = [brakes]

    def brake(dur: float) -> tuple[tuple[float, float], tuple[float, ...] | None]:
        """(rho, allowed) of an approach of duration dur."""
        share, allowed = (1.0, None) if made[0] is None else made[0].at(dur)
        return (1.0 if free[0] else share, 1.0 if free[1] else share), allowed

    def rho(dur: float) -> tuple[float, float]:
        return brake(dur)[0]

    def trial(dur: float) -> tuple[float, Excess | None]:
        rho_d, allowed = brake(dur)
        ratio, excess = check(env, lim, sp, free_end(x, dur, free), dur, r, rho_d, allowed)
        if ratio > 1.0 and made[0] is None:
            made[0] = RatesBrakes(lim, sp, x)
            rho_d, allowed = brake(dur)
            if allowed is not None:
                ratio, excess = check(env, lim, sp, free_end(x, dur, free), dur, r, rho_d,
                                      allowed)
        return ratio, excess

    lo, best = math.nan, None
    for _ in range(MAX_TRIES):
        ratio, excess = trial(d)
        if ratio <= 1.0:
            best = (d, excess)
            break
        lo = d
        if d >= D_MAX_S:
            break
        d = min(D_MAX_S, d * max(GROW_MIN, min(math.sqrt(ratio), GROW_MAX)))
    if best is None:  # nothing fits: the longest tried
        return Approach(coefficients(free_end(x, d, free), d, r, rho(d)), d, False,
                        trial(d)[1])
    hi, hi_excess = best
    while not math.isnan(lo) and hi - lo > REFINE_TOL * hi:
        mid = 0.5 * (lo + hi)
        ratio, excess = trial(mid)
        if ratio <= 1.0:
            hi, hi_excess = mid, excess
        else:
            lo = mid
    return Approach(coefficients(free_end(x, hi, free), hi, r, rho(hi)), hi, True, hi_excess)


def start_offset(a: Approach) -> tuple[Vec3, Vec3]:
    """(e, eps) where the approach starts."""
    k = a.coeffs
    return (float(k[0, 0]), float(k[1, 0]), float(k[2, 0])), \
        (float(k[3, 0]), float(k[4, 0]), float(k[5, 0]))


def _warm() -> None:
    k = np.zeros((6, 9))
    k[:, 7] = 1.0
    k2 = k.copy()
    k2[:, 7] = 0.5
    offset_kernel(k2, 1.0, 0.25)
    reference_kernel(ZERO, ZERO, ZERO, (1.0, 0.0, 0.0, 0.0), ZERO, k, 1.0, 0.0, 0.0)
    reference_rows(ZERO, ZERO, ZERO, (1.0, 0.0, 0.0, 0.0), ZERO, k, 1.0, np.zeros(2))
    kinematic_ratios(k, 1.0, np.zeros(2), np.ones(8))
    offset_rate(ZERO, ZERO)


def warm() -> None:
    """Compile (or load) the kernels once per process, before the first control period."""
    warm_up("fcu.reference.approach", _warm)
