"""Figures of the mission envelope check (docs/missions.md#the-envelope-check): how long a 2 m
leg planned in 1 s (MIS_CRUISE_SPD 3.75 m/s) becomes on each vehicle and which actuator
bounds it, the peak rotor speed and tilt rate of Case I, the rotor speed of hovering at the
worst attitude, and how long the upload check of 500 items takes (waypoints alone, and a mix
of fast legs, keyframes and figures)."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common.config.scenario import VehicleConfig, load_scenario, load_vehicle
from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mission_items import MissionItem, local_xy
from fcu.envelope.feasibility import MARGIN, envelope
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.segments import Move as _Move
from fcu.mission.validation import check_mission
from fcu.reference.trajectory import make_trajectory
from fcu.stages import pose_ref

ROOT = Path(__file__).resolve().parents[1]
WAYPOINT: int = MAV_CMD.MAV_CMD_NAV_WAYPOINT
TAKEOFF: int = MAV_CMD.MAV_CMD_NAV_TAKEOFF
LAND: int = MAV_CMD.MAV_CMD_NAV_LAND
KEYFRAME: int = MAV_CMD.MAV_CMD_WAYPOINT_USER_1
FIGURE: int = MAV_CMD.MAV_CMD_WAYPOINT_USER_2
LOCAL_NED: int = MAV_FRAME.MAV_FRAME_LOCAL_NED


def fast_limits(vehicle: VehicleConfig | None = None) -> MissionLimits:
    """The limits these missions are checked with: top speeds of 3.75 m/s cruise, 1.875 m/s
    climb and 0.9375 m/s descent, so that a leg lasts distance / 2, 1 or 0.5 m/s, fast enough
    for the envelope to stretch the short legs (the timing of the planning figures pinned in
    tests/unit/test_planning_figures.py)."""
    return MissionLimits(cruise_speed_m_s=3.75, takeoff_speed_m_s=1.875,
                         land_speed_m_s=0.9375, vehicle=vehicle)


def waypoints(n: int) -> tuple[MissionItem, ...]:
    """n waypoints 2 m apart, north then back, at 3 m."""
    return tuple(MissionItem(k, LOCAL_NED, WAYPOINT, int(k == 0), 1, 0.0, 0.0, 0.0, math.nan,
                             local_xy(2.0 * (k % 2 + 1)), 0, -3.0) for k in range(n))


def mixed(n: int) -> list[MissionItem]:
    """A takeoff, n - 2 items cycling fast legs to stretch, keyframes and figures, a land."""
    rng = np.random.default_rng(7)
    items = [MissionItem(0, LOCAL_NED, TAKEOFF, 1, 1, 0.0, 0.0, 0.0, math.nan, 0, 0, -3.0)]
    for i in range(1, n - 1):
        north, east = (local_xy(float(v)) for v in rng.uniform(-20.0, 20.0, 2))
        items.append([
            MissionItem(i, LOCAL_NED, WAYPOINT, 0, 1, 0.0, 0.0, 0.0, math.nan, north, east,
                        -5.0),
            MissionItem(i, LOCAL_NED, KEYFRAME, 0, 1, 20.0, 0.3, -0.2, 0.5, north, east, -5.0),
            MissionItem(i, LOCAL_NED, FIGURE, 0, 1, 2.0, 60.0, 2.0, 1.0, 0, 0, -3.0)][i % 3])
    items.append(MissionItem(n - 1, LOCAL_NED, LAND, 0, 1, 0.0, 0.0, 0.0, math.nan, 0, 0, 0.0))
    return items


def main() -> None:
    for name in ("hexa_tilted", "hexa_planar"):
        vehicle = load_vehicle(ROOT / f"config/vehicles/{name}.toml")
        env = envelope(vehicle)
        ex = MissionExecutor(waypoints(3), fast_limits(vehicle))
        ex.start(0.0, (0.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0))
        legs = [t1 - t0 for _, t0, t1 in ex.schedule]
        leg = _Move(1, 0.0, (0.0, 0.0, 3.0), (0.0, 2.0, 0.0), (1.0, 0.0, 0.0, 0.0), None,
                    1.0, 0.0)
        scaling = env.scaling(leg)
        print(f"{name}: 2 m legs at 3.75 m/s planned {legs[1]:.3f} s and {legs[2]:.3f} s "
              f"(1 s unstretched, where {env.explain(scaling.excess(1.0))}; rotor speed "
              f"alone would allow {scaling._speed_bound():.3f} s)")

    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    limits = fast_limits(vehicle)
    env = envelope(vehicle)
    traj = make_trajectory(load_scenario(ROOT / "config/scenarios/case1_figure8.toml")
                           .trajectory)
    samples = [traj.sample(k * 0.01) for k in range(16001)]
    peak = max(env.peak(ref).speed_rad_s for ref in samples)
    print(f"Case I peak rotor speed (feed-forward, every 10 ms): {peak:.0f} rad/s, "
          f"limit {env.limit:.0f} ({MARGIN:.0%} of {vehicle.rotor_speed_max_rad_s:.0f})")
    om = np.vstack([env.omega_sq(ref) for ref in samples])
    tilt = np.unwrap(np.arctan2(om[:, 0::2], om[:, 1::2]), axis=0)
    tilt_peak = float(np.abs(np.diff(tilt, axis=0)).max() / 0.01)
    print(f"Case I peak tilt rate (feed-forward, every 10 ms): {tilt_peak:.2f} rad/s, limit "
          f"{env.tilt_limit:.1f} ({env.tilt_margin:.0%} of {env.tilt_rate_max:.1f})")

    rng = np.random.default_rng(0)
    worst = 0.0
    for q in rng.normal(size=(20000, 4)):
        q /= np.linalg.norm(q)
        worst = max(worst, env.peak(pose_ref((0.0, 0.0, 0.0), tuple(q))).speed_rad_s)
    print(f"hover at the worst of 20,000 attitudes: {worst:.0f} rad/s = "
          f"{worst / vehicle.rotor_speed_max_rad_s:.0%} of w_max")

    for what, items in (("500 waypoints", list(waypoints(500))),
                        ("500 mixed items", mixed(500))):
        t0 = time.perf_counter()
        result = check_mission(items, limits)
        print(f"upload check of {what}: {time.perf_counter() - t0:.3f} s "
              f"(MAV_MISSION_RESULT {result.result})")


if __name__ == "__main__":
    main()
