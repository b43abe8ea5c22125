"""The last phase of a landing and the land detector (PX4's, simplified); pure, no I/O.

Once the planned descent ends (LAND, RTL, or a mission's last NAV_LAND), the set-point keeps
going down at the land speed, at most `TOUCHDOWN_DEPTH_M` below the planned end, so the
vehicle reaches the ground whatever its tracking error (`touchdown_ref`). The vehicle is on
the ground once it has been still, held up and lifting little for `LANDED_STILL_S`
(`held_up_and_still`); disarmed, at rest below `LANDED_ALTITUDE_M` (`landed_state`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from fcu.dualquat import Quat, Vec3
from fcu.tracker import Reference, VehicleState

_ZERO: Vec3 = (0.0, 0.0, 0.0)
LANDED_ALTITUDE_M = 0.05
TAKEOFF_ALTITUDE_M = 0.1
LANDED_SPEED_M_S = 0.2
LANDED_STILL_S = 0.3
LANDED_LIFT_RATIO = 0.9
TOUCHDOWN_DEPTH_M = 1.0
TOUCHDOWN_BLOCKED_M = 0.1


class Touchdown(NamedTuple):
    """The last phase of a landing: the set-point sinks from (p, q) from t_us on."""

    t_us: int
    p_enu_m: Vec3
    q_enu_flu: Quat


def _speed(s: VehicleState) -> float:
    return math.sqrt(sum(v * v for v in s.v_flu_m_s))


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


def touchdown_ref(td: Touchdown, t_us: int, land_speed_m_s: float) -> Reference:
    """The set-point sinking at the land speed from the planned end, down to
    TOUCHDOWN_DEPTH_M below it."""
    depth = land_speed_m_s * (t_us - td.t_us) * 1e-6
    v = (0.0, 0.0, -land_speed_m_s)
    if depth >= TOUCHDOWN_DEPTH_M:
        depth, v = TOUCHDOWN_DEPTH_M, _ZERO
    x, y, z = td.p_enu_m
    return Reference((x, y, z - depth), td.q_enu_flu, v, _ZERO, _ZERO, _ZERO)


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
