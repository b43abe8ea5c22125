"""The last phase of a landing and the land detector (PX4's, simplified); pure, no I/O.

Once the planned descent ends (LAND, RTL, or a mission's last NAV_LAND), the set-point keeps
going down, so the vehicle reaches the ground whatever its tracking error and wherever the
ground is (`touchdown_ref`):

- it sinks at the touchdown speed, reached from rest over `TOUCHDOWN_RAMP_S` (the velocity
  never steps), at most `TOUCHDOWN_DEPTH_M` below the planned end (with no ground below the
  vehicle then hovers there);
- never more than `TOUCHDOWN_BELOW_M` below the vehicle: once the ground holds the vehicle,
  the set-point stays just below it (enough for the land detector to see it held up) instead
  of sinking on into the ground;
- the touchdown speed is the land speed, capped by the gains (`touchdown_speed_cap`): on the
  ground the position loop pushes down with k_d v + k_p TOUCHDOWN_BELOW_M, and that push
  must stay well below g, or the rotors' thrust reverses and every tilt flips half a turn
  (measured on both presets at 0.89 m/s and above with the default gains, before this cap).

The vehicle is on the ground once it has been still, held up and lifting little for
`LANDED_STILL_S` (`held_up_and_still`); disarmed, at rest below `LANDED_ALTITUDE_M`
(`landed_state`). `Descent` is the commander's landing state: LAND's plan, the touchdown,
the land detector's and the landed state.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from common.quaternion import norm3
from fcu.control.dualquat import Quat, Vec3
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.modes import auto_plans
from fcu.stages import Reference, VehicleState

_ZERO: Vec3 = (0.0, 0.0, 0.0)
LANDED_ALTITUDE_M = 0.05
TAKEOFF_ALTITUDE_M = 0.1
LANDED_SPEED_M_S = 0.2
LANDED_STILL_S = 0.3
LANDED_LIFT_RATIO = 0.9
TOUCHDOWN_DEPTH_M = 1.0
TOUCHDOWN_BLOCKED_M = 0.1
TOUCHDOWN_BELOW_M = 0.15  # the sinking set-point's furthest below the vehicle
TOUCHDOWN_RAMP_S = 0.25  # the sink's speed is reached from rest in this long
TOUCHDOWN_PUSH = 0.6  # share of g the damping may push down with at the touchdown speed


class Touchdown(NamedTuple):
    """The last phase of a landing: the set-point sinks from (p, q) from t_us on."""

    t_us: int
    p_enu_m: Vec3
    q_enu_flu: Quat


def _speed(s: VehicleState) -> float:
    return norm3(s.v_flu_m_s)


def landed_state(armed: bool, on_ground: bool, s: VehicleState) -> bool:
    """The landed state at a new state: a disarmed vehicle at rest at ground level is on the
    ground; an armed one leaves it when it rises or moves, and comes back to it only through
    the land detector (`held_up_and_still`), never from its altitude alone: with no ground
    below (Case II) a hover at z = 0 is not a landing."""
    speed = _speed(s)
    if not armed:
        return s.p_enu_m[2] < LANDED_ALTITUDE_M and speed < LANDED_SPEED_M_S
    if on_ground and (s.p_enu_m[2] > TAKEOFF_ALTITUDE_M or speed > LANDED_SPEED_M_S):
        return False
    return on_ground


def touchdown_speed_cap(kd_m: float, gravity_m_s2: float) -> float:
    """The fastest touchdown speed the position loop lands at without pushing down by more
    than TOUCHDOWN_PUSH g with its damping `kd_m` (1/s, the largest of the dual part's k_d)."""
    return TOUCHDOWN_PUSH * gravity_m_s2 / kd_m if kd_m > 0.0 else math.inf


def touchdown_ref(td: Touchdown, t_us: int, speed_m_s: float,
                  vehicle_z_m: float | None = None) -> Reference:
    """The set-point sinking at `speed_m_s` from the planned end (reached from rest over
    TOUCHDOWN_RAMP_S), down to TOUCHDOWN_DEPTH_M below it, and never more than
    TOUCHDOWN_BELOW_M below the vehicle's height `vehicle_z_m` (ENU up) when given."""
    tau = max(0.0, (t_us - td.t_us) * 1e-6)
    ramp = TOUCHDOWN_RAMP_S
    if tau < ramp:
        depth, sink, acc = speed_m_s * tau * tau / (2.0 * ramp), speed_m_s * tau / ramp, \
            speed_m_s / ramp
    else:
        depth, sink, acc = speed_m_s * (tau - 0.5 * ramp), speed_m_s, 0.0
    if depth >= TOUCHDOWN_DEPTH_M:
        depth, sink, acc = TOUCHDOWN_DEPTH_M, 0.0, 0.0
    x, y, z = td.p_enu_m
    z_ref = z - depth
    if vehicle_z_m is not None and z_ref < vehicle_z_m - TOUCHDOWN_BELOW_M:
        z_ref, acc = vehicle_z_m - TOUCHDOWN_BELOW_M, 0.0  # held up: the ground is here
    return Reference((x, y, z_ref), td.q_enu_flu, (0.0, 0.0, -sink), (0.0, 0.0, -acc),
                     _ZERO, _ZERO)


def held_up_and_still(s: VehicleState, ref: Reference | None, lift_n: float,
                      weight_n: float) -> bool:
    """As PX4's land detector: still (speed below LANDED_SPEED_M_S), held up (at the ground
    plane's height, or the set-point more than TOUCHDOWN_BLOCKED_M below the vehicle) and
    with little lift (the commanded force along the world's up below LANDED_LIFT_RATIO of
    the weight: something else carries the rest). A vehicle still in the air needs its whole
    weight in lift."""
    blocked = s.p_enu_m[2] < LANDED_ALTITUDE_M or (
        ref is not None and s.p_enu_m[2] - ref.p_enu_m[2] > TOUCHDOWN_BLOCKED_M)
    return not (_speed(s) >= LANDED_SPEED_M_S or not blocked or
                lift_n > LANDED_LIFT_RATIO * weight_n)


class Descent:
    """The landing's state: LAND's planned descent (`plan`), the touchdown that ends a
    landing (`touchdown`), the land detector's stillness and the landed state
    (`on_ground`); `speed_cap_m_s` is the touchdown speed the gains land at."""

    def __init__(self) -> None:
        self.plan: MissionExecutor | None = None  # LAND's descent
        self.touchdown: Touchdown | None = None
        self.still_since_us: int | None = None
        self.on_ground = True  # the landed state (`update_landed`)
        self.speed_cap_m_s = math.inf  # set from the gains (`touchdown_speed_cap`)

    def end(self) -> None:
        """No landing under way: LAND's plan and a touchdown dropped."""
        self.plan = None
        self.touchdown = None

    def start(self, t_s: float, start: Reference, limits: MissionLimits) -> None:
        """LAND's descent planned from `start` at `t_s` (flight clock)."""
        self.plan = MissionExecutor(auto_plans.land(), limits)
        self.plan.start(t_s, start.p_enu_m, start.q_enu_flu)
        self.touchdown = None

    def step(self, t_us: int) -> tuple[Reference, bool]:
        """LAND's planned descent at `t_us`, and whether it has ended (then the touchdown
        begins: `begin_touchdown`)."""
        plan = self.plan
        assert plan is not None
        t_s = t_us * 1e-6
        plan.update(t_s)
        return plan.sample(t_s), plan.completed

    def begin_touchdown(self, t_us: int, ref: Reference) -> None:
        """The set-point sinks from `ref`'s pose from `t_us` on; from here on only the land
        detector's evidence counts."""
        self.touchdown = Touchdown(t_us, ref.p_enu_m, ref.q_enu_flu)
        self.still_since_us = None
        self.on_ground = False

    def speed_m_s(self, land_speed_m_s: float) -> float:
        """The land speed (MIS_LAND_SPD), capped by what the gains land at."""
        return min(land_speed_m_s, self.speed_cap_m_s)

    def touchdown_ref(self, t_us: int, land_speed_m_s: float,
                      state: VehicleState | None) -> Reference:
        assert self.touchdown is not None
        z = state.p_enu_m[2] if state is not None else None
        return touchdown_ref(self.touchdown, t_us, self.speed_m_s(land_speed_m_s), z)

    def update_landed(self, armed: bool, state: VehicleState | None) -> None:
        """The landed state at a new state (`landed_state`)."""
        if state is not None:
            self.on_ground = landed_state(armed, self.on_ground, state)

    def detector(self, t_us: int, state: VehicleState | None, ref: Reference | None,
                 lift_n: float, weight_n: float) -> bool:
        """During a touchdown: True once the vehicle is on the ground: held up and still for
        LANDED_STILL_S (`held_up_and_still`)."""
        if self.touchdown is None or state is None:
            return False
        if not held_up_and_still(state, ref, lift_n, weight_n):
            self.still_since_us = None
        elif self.still_since_us is None:
            self.still_since_us = t_us
        if self.still_since_us is not None and \
                (t_us - self.still_since_us) * 1e-6 >= LANDED_STILL_S:
            self.on_ground = True
        return self.on_ground
