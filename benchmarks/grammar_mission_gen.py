"""Random missions built phase by phase (benchmarks/grammar_missions.py): a pure generator,
`draw_mission(rng, dist)`, with stated distributions (`PhaseDistributions`). A generator
beside benchmarks/random_mission_gen.py (cruise legs, keyframes and figures from home) and
benchmarks/phase_missions.py's, built differently from both: a mission is first drawn as a
list of phases (a grammar: start, take-off, a body of blocks, an ending), then each phase
is turned into items, with positions drawn as absolute points in a disc around the start
(not legs from the last point), attitudes as absolute roll, pitch and yaw, and figures
among the blocks.

A mission (`PhaseMission`):

* start: on the ground at home (the origin) with probability 1 - `p_away`, else at a point
  uniform over the disc of radius `start_radius_m` (uniform over the area);
* take-off (item 0): NAV_TAKEOFF to an altitude uniform in [takeoff_alt_m], climb time p2 0
  (timed by MIS_TKO_SPD) with probability `p_takeoff_speed_timed`, else uniform in
  [takeoff_time_s];
* body: `n_blocks` uniform in [n_blocks] blocks, each a kind drawn with `block_weights`:
  - leg: NAV_WAYPOINT to a point (below), hold p1 0 with probability 0.5, else uniform in
    [hold_s]; yaw p4 NaN with probability `p_yaw_nan`, else uniform in [-180, 180) deg;
  - loiter: NAV_LOITER_TIME at a point for p1 uniform in [hold_s];
  - keyframe: WAYPOINT_USER_1 to a point and an absolute attitude (roll, pitch normal with
    sigma `tilt_sigma_deg` clipped to `tilt_max_deg`, yaw uniform), time p1 uniform in
    [keyframe_time_s];
  - figure: WAYPOINT_USER_2, amplitude p1 uniform in [figure_amp_m], duration p2 uniform in
    [figure_time_s]; its axis NED (p3, p4, z): about the vertical with a length uniform in
    [-figure_yaw_turns, figure_yaw_turns] with probability 1/3, else a direction uniform on
    the sphere with a length uniform in [0.005, figure_still_len] (an almost still attitude)
    or [0.005, figure_axis_len], each with probability 1/3;
  - speed: DO_CHANGE_SPEED (178), p1 a speed type uniform in 0..3; p2 -1 (no change) or -2
    (the parameter's) each with probability `p_speed_special` / 2, else log-uniform in
    [cruise_m_s] (types 0, 1), [climb_m_s] (2) or [land_m_s] (3); p3 (throttle) -1;
  - touch-and-go: NAV_LAND (yaw NaN) then NAV_TAKEOFF to an altitude uniform in
    [takeoff_alt_m] (p2 0);
  a point: north and east at a distance triangular in [0, point_radius_m] (mode 0) from
  the start in a uniform direction, altitude uniform in [point_alt_m];
* ending: NAV_LAND (yaw NaN) with probability `p_land`, else the mission ends in the air.

Per mission the parameters MIS_CRUISE_SPD (log-uniform in [cruise_m_s]) and MIS_LAND_SPD
(log-uniform in [land_m_s]) and a file format (`FORMATS`, uniform): the project's TOML
(local NED), QGC WPL in the local frame, QGC WPL in a global frame (relative altitude or
AMSL, equally likely) and QGC's .plan (global, relative altitude; DO_CHANGE_SPEED in frame 2
as QGC writes it). Everything is drawn from the given numpy Generator only: the same seed
gives the same mission.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mission_items import HomePosition, MissionItem, local_xy, to_global
from fcu.control.dualquat import q_log, q_mul

LOCAL_NED: int = MAV_FRAME.MAV_FRAME_LOCAL_NED
MISSION_FRAME: int = MAV_FRAME.MAV_FRAME_MISSION  # 2: QGC's frame for DO_ items
NAV_TAKEOFF: int = MAV_CMD.MAV_CMD_NAV_TAKEOFF
NAV_WAYPOINT: int = MAV_CMD.MAV_CMD_NAV_WAYPOINT
NAV_LOITER_TIME: int = MAV_CMD.MAV_CMD_NAV_LOITER_TIME
NAV_LAND: int = MAV_CMD.MAV_CMD_NAV_LAND
DO_CHANGE_SPEED: int = MAV_CMD.MAV_CMD_DO_CHANGE_SPEED
KEYFRAME: int = MAV_CMD.MAV_CMD_WAYPOINT_USER_1
FIGURE: int = MAV_CMD.MAV_CMD_WAYPOINT_USER_2

BLOCKS = ("leg", "loiter", "keyframe", "figure", "speed", "touch_and_go")
FORMATS = ("toml", "wpl_local", "wpl_global", "plan")
EXTENSION = {"toml": ".toml", "wpl_local": ".waypoints", "wpl_global": ".waypoints",
             "plan": ".plan"}


@dataclass(frozen=True)
class PhaseDistributions:
    """The distributions of `draw_mission` (module docstring); ranges are (low, high)."""

    p_away: float = 0.5
    start_radius_m: float = 5.0
    takeoff_alt_m: tuple[float, float] = (0.2, 3.0)  # uniform
    p_takeoff_speed_timed: float = 0.75
    takeoff_time_s: tuple[float, float] = (1.0, 6.0)  # uniform
    n_blocks: tuple[int, int] = (1, 5)  # uniform integers, inclusive
    # leg, loiter, keyframe, figure, speed, touch-and-go
    block_weights: tuple[float, ...] = (0.30, 0.12, 0.16, 0.10, 0.20, 0.12)
    point_radius_m: float = 6.0  # triangular, mode 0
    point_alt_m: tuple[float, float] = (0.3, 3.5)  # uniform
    hold_s: tuple[float, float] = (0.2, 3.0)  # uniform
    p_yaw_nan: float = 0.6
    tilt_sigma_deg: float = 12.0
    tilt_max_deg: float = 35.0
    keyframe_time_s: tuple[float, float] = (1.5, 10.0)  # uniform
    figure_amp_m: tuple[float, float] = (0.2, 1.2)  # uniform
    figure_time_s: tuple[float, float] = (8.0, 24.0)  # uniform
    figure_yaw_turns: float = 1.0
    figure_axis_len: float = 0.4
    figure_still_len: float = 0.02  # an almost still attitude (a zero axis is refused)
    p_speed_special: float = 0.3
    cruise_m_s: tuple[float, float] = (0.3, 8.0)  # log-uniform
    climb_m_s: tuple[float, float] = (0.2, 5.0)  # log-uniform
    land_m_s: tuple[float, float] = (0.05, 5.0)  # log-uniform
    p_land: float = 0.7
    formats: tuple[str, ...] = field(default=FORMATS)


DEFAULT = PhaseDistributions()


@dataclass(frozen=True)
class PhaseMission:
    """One drawn mission: its items (local NED), phases, start, parameters and file
    format."""

    items: tuple[MissionItem, ...]
    phases: tuple[str, ...]  # "takeoff", then the blocks, then "land" or "end_in_air"
    start_enu_m: tuple[float, float, float]
    params: dict[str, float]
    fmt: str  # one of FORMATS


def _logu(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(math.exp(rng.uniform(math.log(lo_hi[0]), math.log(lo_hi[1]))))


def _u(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(rng.uniform(lo_hi[0], lo_hi[1]))


def _item(command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0, p4: float = 0.0,
          north: float = 0.0, east: float = 0.0, z: float = 0.0,
          frame: int = LOCAL_NED) -> MissionItem:
    return MissionItem(seq=0, frame=frame, command=command, current=0, autocontinue=1,
                       param1=p1, param2=p2, param3=p3, param4=p4, x=local_xy(north),
                       y=local_xy(east), z=z)


def _point(rng: np.random.Generator, start_ne: tuple[float, float],
           dist: PhaseDistributions) -> tuple[float, float, float]:
    """(north, east, down) of a point around the start (module docstring)."""
    r = float(rng.triangular(0.0, 0.0, dist.point_radius_m))
    a = float(rng.uniform(-math.pi, math.pi))
    return (start_ne[0] + r * math.cos(a), start_ne[1] + r * math.sin(a),
            -_u(rng, dist.point_alt_m))


def _rpy_quat(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """NED-to-FRD attitude of ZYX Euler angles (rad)."""
    def axis(i: int, a: float) -> tuple[float, float, float, float]:
        v = [0.0, 0.0, 0.0]
        v[i] = math.sin(a / 2.0)
        return (math.cos(a / 2.0), v[0], v[1], v[2])
    return q_mul(q_mul(axis(2, yaw), axis(1, pitch)), axis(0, roll))


def _speed_item(rng: np.random.Generator, dist: PhaseDistributions) -> MissionItem:
    kind = int(rng.integers(0, 4))
    u = float(rng.uniform())
    if u < dist.p_speed_special / 2.0:
        speed = -1.0
    elif u < dist.p_speed_special:
        speed = -2.0
    else:
        speed = _logu(rng, (dist.cruise_m_s, dist.cruise_m_s, dist.climb_m_s,
                            dist.land_m_s)[kind])
    return _item(DO_CHANGE_SPEED, p1=float(kind), p2=speed, p3=-1.0)


def _block(kind: str, rng: np.random.Generator, start_ne: tuple[float, float],
           dist: PhaseDistributions) -> list[MissionItem]:
    if kind == "leg":
        n, e, d = _point(rng, start_ne, dist)
        hold = 0.0 if rng.uniform() < 0.5 else _u(rng, dist.hold_s)
        yaw = math.nan if rng.uniform() < dist.p_yaw_nan else float(rng.uniform(-180, 180))
        return [_item(NAV_WAYPOINT, p1=hold, p4=yaw, north=n, east=e, z=d)]
    if kind == "loiter":
        n, e, d = _point(rng, start_ne, dist)
        return [_item(NAV_LOITER_TIME, p1=_u(rng, dist.hold_s), north=n, east=e, z=d)]
    if kind == "keyframe":
        n, e, d = _point(rng, start_ne, dist)
        lim = dist.tilt_max_deg
        roll, pitch = (math.radians(float(np.clip(rng.normal(0.0, dist.tilt_sigma_deg),
                                                  -lim, lim))) for _ in range(2))
        yaw = float(rng.uniform(-math.pi, math.pi))
        rv = q_log(_rpy_quat(roll, pitch, yaw))
        return [_item(KEYFRAME, p1=_u(rng, dist.keyframe_time_s), p2=rv[0], p3=rv[1],
                      p4=rv[2], north=n, east=e, z=d)]
    if kind == "figure":
        mode = int(rng.integers(0, 3))
        if mode == 1:
            axis = (0.0, 0.0, _u(rng, (-dist.figure_yaw_turns, dist.figure_yaw_turns)))
        else:
            v = rng.normal(size=3)
            top = dist.figure_axis_len if mode == 2 else dist.figure_still_len
            v = v / max(float(np.linalg.norm(v)), 1e-9) * rng.uniform(0.005, top)
            axis = (float(v[0]), float(v[1]), float(v[2]))
        return [_item(FIGURE, p1=_u(rng, dist.figure_amp_m), p2=_u(rng, dist.figure_time_s),
                      p3=axis[0], p4=axis[1], z=axis[2])]
    if kind == "speed":
        return [_speed_item(rng, dist)]
    if kind == "touch_and_go":
        alt = _u(rng, dist.takeoff_alt_m)
        return [_item(NAV_LAND, p4=math.nan), _item(NAV_TAKEOFF, p4=math.nan, z=-alt)]
    raise ValueError(kind)


def draw_mission(rng: np.random.Generator,
                 dist: PhaseDistributions = DEFAULT) -> PhaseMission:
    """One mission (module docstring): items seq 0..n-1 in local NED."""
    if rng.uniform() < dist.p_away:
        r = dist.start_radius_m * math.sqrt(float(rng.uniform()))
        a = float(rng.uniform(-math.pi, math.pi))
        start_ne = (r * math.cos(a), r * math.sin(a))
    else:
        start_ne = (0.0, 0.0)
    alt = _u(rng, dist.takeoff_alt_m)
    climb = 0.0 if rng.uniform() < dist.p_takeoff_speed_timed else _u(rng, dist.takeoff_time_s)
    items = [_item(NAV_TAKEOFF, p2=climb, p4=math.nan, north=start_ne[0], east=start_ne[1],
                   z=-alt)]
    phases = ["takeoff"]
    weights = np.asarray(dist.block_weights, dtype=float)
    n_blocks = int(rng.integers(dist.n_blocks[0], dist.n_blocks[1] + 1))
    for _ in range(n_blocks):
        kind = BLOCKS[int(rng.choice(len(BLOCKS), p=weights / weights.sum()))]
        phases.append(kind)
        items += _block(kind, rng, start_ne, dist)
    if rng.uniform() < dist.p_land:
        items.append(_item(NAV_LAND, p4=math.nan))
        phases.append("land")
    else:
        phases.append("end_in_air")
    params = {"MIS_CRUISE_SPD": _logu(rng, dist.cruise_m_s),
              "MIS_LAND_SPD": _logu(rng, dist.land_m_s)}
    fmt = dist.formats[int(rng.integers(0, len(dist.formats)))]
    seqd = tuple(it._replace(seq=i, current=int(i == 0)) for i, it in enumerate(items))
    # The start, ENU (north, east -> y, x), on the ground.
    return PhaseMission(seqd, tuple(phases), (start_ne[1], start_ne[0], 0.0), params, fmt)


def file_items(mission: PhaseMission, home: HomePosition) -> list[MissionItem]:
    """The items as the mission's file format holds them: local NED (toml, wpl_local) or
    converted to a global frame through `home` (wpl_global: relative altitude or AMSL by
    the item count's parity; plan: relative altitude, DO_CHANGE_SPEED in frame 2)."""
    items = list(mission.items)
    if mission.fmt in ("toml", "wpl_local"):
        return items
    if mission.fmt == "wpl_global":
        frame = (MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT if len(items) % 2
                 else MAV_FRAME.MAV_FRAME_GLOBAL)
        return [to_global(it, home, frame) for it in items]
    return [to_global(it, home) if it.command != DO_CHANGE_SPEED
            else it._replace(frame=MISSION_FRAME) for it in items]


def item_phase(items: tuple[MissionItem, ...] | list[MissionItem], seq: int) -> str:
    """The phase an item belongs to: takeoff (item 0), touch_and_go (a NAV_LAND with items
    after it, and the NAV_TAKEOFF after it), land (the last item's NAV_LAND), cruise
    (waypoints, loiters), keyframe_figure (keyframes, figures), speed (DO_CHANGE_SPEED)."""
    cmd = items[seq].command
    if cmd == NAV_TAKEOFF:
        return "takeoff" if seq == 0 else "touch_and_go"
    if cmd == NAV_LAND:
        return "land" if seq == len(items) - 1 else "touch_and_go"
    if cmd in (NAV_WAYPOINT, NAV_LOITER_TIME):
        return "cruise"
    if cmd in (KEYFRAME, FIGURE):
        return "keyframe_figure"
    return "speed" if cmd == DO_CHANGE_SPEED else str(cmd)
