"""Random missions for the random-mission campaign (benchmarks/random_missions.py): a pure
generator, `random_mission(rng, dist)`, with stated distributions (`MissionDistributions`).

A mission (MAVLink local NED items, `common.wire.mission_items.MissionItem`):

* item 0: NAV_TAKEOFF to an altitude uniform in [takeoff_alt_m] (p2 = 0: timed by the
  takeoff speed, yaw NaN); the vehicle starts on the ground at the origin;
* then `n_draws` uniform in [n_draws] (inclusive) draws, each a kind chosen with
  `kind_weights` (waypoint, keyframe, figure):
  - waypoint: a leg of length log-uniform in [leg_m] in a direction uniform on the sphere;
    a vertical component that would take the altitude below `min_alt_m` is flipped upward,
    a leg that would leave `max_radius_m` has its horizontal part flipped toward the origin;
    hold p1 uniform in [hold_s]; yaw p4 NaN with probability `p_yaw_nan`, else uniform in
    [-180, 180) deg;
  - keyframe (POSE_KEYFRAME): a position change drawn as a leg; an attitude change of an angle
    uniform in [0, max_turn_deg] about an axis uniform on the sphere, applied in the body
    frame to the attitude the previous items end at (so the shortest path turns by that
    angle); time p1 log-uniform in [keyframe_time_s]; then a hold uniform in [hold_s] as a
    NAV_LOITER_TIME at the keyframe's position (only if >= MIN_HOLD_S);
  - figure (FIGURE_EIGHT): amplitude p1 uniform in [figure_amp_m], period p2 uniform in
    [figure_period_s], axis (p3, p4, z) NED of a direction uniform on the sphere and a
    length uniform in [figure_axis_len] (the attitude turns by 2 pi x that length, about it);
    the figure only climbs (ENU offset z = A (1 - cos 2T) >= 0) and returns to its start;
* last, with probability `p_land`, NAV_LAND (yaw NaN).

The cruise speed (the FCU parameter MIS_CRUISE_SPD) is `random_cruise_speed`: log-uniform in
[cruise_m_s]. Everything is drawn from the given numpy Generator only: the same seed gives
the same mission.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mission_items import MissionItem, local_xy
from fcu.control.dualquat import Quat, q_exp, q_log, q_mul

LOCAL_NED: int = MAV_FRAME.MAV_FRAME_LOCAL_NED
NAV_WAYPOINT: int = MAV_CMD.MAV_CMD_NAV_WAYPOINT
NAV_LOITER_TIME: int = MAV_CMD.MAV_CMD_NAV_LOITER_TIME
NAV_LAND: int = MAV_CMD.MAV_CMD_NAV_LAND
NAV_TAKEOFF: int = MAV_CMD.MAV_CMD_NAV_TAKEOFF
POSE_KEYFRAME: int = MAV_CMD.MAV_CMD_WAYPOINT_USER_1
FIGURE_EIGHT: int = MAV_CMD.MAV_CMD_WAYPOINT_USER_2
KINDS = ("waypoint", "keyframe", "figure")
MIN_HOLD_S = 0.05  # a keyframe's hold below this adds no loiter item
_Q_ID: Quat = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MissionDistributions:
    """The distributions of `random_mission` (module docstring); ranges are (low, high)."""

    takeoff_alt_m: tuple[float, float] = (1.0, 5.0)  # uniform
    n_draws: tuple[int, int] = (2, 12)  # uniform integers, inclusive
    kind_weights: tuple[float, float, float] = (0.5, 0.3, 0.2)  # waypoint, keyframe, figure
    leg_m: tuple[float, float] = (0.2, 30.0)  # log-uniform
    hold_s: tuple[float, float] = (0.0, 2.0)  # uniform
    p_yaw_nan: float = 0.5
    max_turn_deg: float = 180.0  # keyframe attitude change: uniform angle in [0, this]
    keyframe_time_s: tuple[float, float] = (0.5, 10.0)  # log-uniform
    figure_amp_m: tuple[float, float] = (0.2, 2.0)  # uniform
    figure_period_s: tuple[float, float] = (5.0, 30.0)  # uniform
    figure_axis_len: tuple[float, float] = (0.1, 1.0)  # uniform
    p_land: float = 0.5
    cruise_m_s: tuple[float, float] = (0.2, 15.0)  # log-uniform
    min_alt_m: float = 0.5
    max_radius_m: float = 900.0  # inside the FCU's default geofence (GF_MAX_DIST 1000 m)


DEFAULT = MissionDistributions()


def _loguniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    lo, hi = lo_hi
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _uniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(rng.uniform(lo_hi[0], lo_hi[1]))


def _direction(rng: np.random.Generator) -> tuple[float, float, float]:
    """A unit vector uniform on the sphere."""
    while True:
        v = rng.normal(size=3)
        n = float(np.linalg.norm(v))
        if n > 1e-9:
            return (float(v[0] / n), float(v[1] / n), float(v[2] / n))


def random_cruise_speed(rng: np.random.Generator, dist: MissionDistributions = DEFAULT) -> float:
    """MIS_CRUISE_SPD for one mission (m/s), log-uniform in dist.cruise_m_s."""
    return _loguniform(rng, dist.cruise_m_s)


def _item(seq: int, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0,
          p4: float = 0.0, p_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
          z: float | None = None) -> MissionItem:
    return MissionItem(seq=seq, frame=LOCAL_NED, command=command, current=int(seq == 0),
                       autocontinue=1, param1=p1, param2=p2, param3=p3, param4=p4,
                       x=local_xy(p_ned_m[0]), y=local_xy(p_ned_m[1]),
                       z=p_ned_m[2] if z is None else z)


def _leg(rng: np.random.Generator, p_ned_m: tuple[float, float, float],
         dist: MissionDistributions) -> tuple[tuple[float, float, float], float]:
    """(the leg's end, its length) from p_ned_m, altitude >= min_alt_m, inside max_radius_m."""
    length = _loguniform(rng, dist.leg_m)
    d = _direction(rng)
    n, e, down = (length * d[0], length * d[1], length * d[2])
    if -(p_ned_m[2] + down) < dist.min_alt_m:
        down = -abs(down)  # climb instead (the altitude is >= min_alt_m already)
    if math.hypot(p_ned_m[0] + n, p_ned_m[1] + e) > dist.max_radius_m:
        n, e = -n, -e
    return (p_ned_m[0] + n, p_ned_m[1] + e, p_ned_m[2] + down), length


def _yaw_deg(rng: np.random.Generator, dist: MissionDistributions) -> float:
    if rng.uniform() < dist.p_yaw_nan:
        return math.nan
    return float(rng.uniform(-180.0, 180.0))


def random_mission(rng: np.random.Generator,
                   dist: MissionDistributions = DEFAULT) -> list[MissionItem]:
    """One random mission (module docstring), items seq 0..n-1 in local NED."""
    alt = _uniform(rng, dist.takeoff_alt_m)
    p: tuple[float, float, float] = (0.0, 0.0, -alt)
    q: Quat = _Q_ID  # the planned attitude, NED/FRD
    items = [_item(0, NAV_TAKEOFF, p4=math.nan, z=-alt)]
    kinds = np.asarray(dist.kind_weights, dtype=float)
    kinds = kinds / kinds.sum()
    n_draws = int(rng.integers(dist.n_draws[0], dist.n_draws[1] + 1))
    for _ in range(n_draws):
        kind = KINDS[int(rng.choice(len(KINDS), p=kinds))]
        seq = len(items)
        if kind == "waypoint":
            p, _ = _leg(rng, p, dist)
            hold = _uniform(rng, dist.hold_s)
            yaw = _yaw_deg(rng, dist)
            items.append(_item(seq, NAV_WAYPOINT, p1=hold, p4=yaw, p_ned_m=p))
            if not math.isnan(yaw):
                q = q_exp((0.0, 0.0, math.radians(yaw)))
        elif kind == "keyframe":
            p, _ = _leg(rng, p, dist)
            angle = math.radians(float(rng.uniform(0.0, dist.max_turn_deg)))
            axis = _direction(rng)
            q = q_mul(q, q_exp((angle * axis[0], angle * axis[1], angle * axis[2])))
            rv = q_log(q)
            t = _loguniform(rng, dist.keyframe_time_s)
            items.append(_item(seq, POSE_KEYFRAME, p1=t, p2=rv[0], p3=rv[1], p4=rv[2],
                               p_ned_m=p))
            hold = _uniform(rng, dist.hold_s)
            if hold >= MIN_HOLD_S:
                items.append(_item(seq + 1, NAV_LOITER_TIME, p1=hold, p_ned_m=p))
        else:
            amp = _uniform(rng, dist.figure_amp_m)
            period = _uniform(rng, dist.figure_period_s)
            axis = _direction(rng)
            k = _uniform(rng, dist.figure_axis_len)
            n_ned = (k * axis[0], k * axis[1], k * axis[2])
            items.append(_item(seq, FIGURE_EIGHT, p1=amp, p2=period, p3=n_ned[0],
                               p4=n_ned[1], z=n_ned[2]))
            turn = 2.0 * math.pi
            q = q_mul(q_exp((turn * n_ned[0], turn * n_ned[1], turn * n_ned[2])), q)
    if rng.uniform() < dist.p_land:
        items.append(_item(len(items), NAV_LAND, p4=math.nan))
    return items


def item_kind(item: MissionItem) -> str:
    """The generator's name for an item's command."""
    return {NAV_TAKEOFF: "takeoff", NAV_WAYPOINT: "waypoint", NAV_LOITER_TIME: "hold",
            NAV_LAND: "land", POSE_KEYFRAME: "keyframe",
            FIGURE_EIGHT: "figure"}.get(item.command, str(item.command))


def leg_lengths_m(items: list[MissionItem]) -> list[tuple[int, float]]:
    """(seq, length) of every speed-timed position move (waypoints, holds, takeoff, landing)
    along the planned positions from the origin."""
    p = (0.0, 0.0, 0.0)
    out: list[tuple[int, float]] = []
    for it in items:
        if it.command == NAV_TAKEOFF:
            new = (p[0], p[1], it.z)
        elif it.command in (NAV_WAYPOINT, NAV_LOITER_TIME, POSE_KEYFRAME):
            new = (it.x_m, it.y_m, it.z)
        elif it.command == NAV_LAND:
            new = (p[0], p[1], 0.0)
        else:
            continue
        if it.command != POSE_KEYFRAME:
            out.append((it.seq, math.dist(p, new)))
        p = new
    return out
