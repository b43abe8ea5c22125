"""Figures of the mission envelope check (README, section Missions): how long a 2 m leg at
MIS_CRUISE_SPD 2 m/s becomes, the peak rotor speed of Case I, the rotor speed of hovering at
the worst attitude, and how long the upload check of 500 items takes."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common.config import load_scenario, load_vehicle
from common.mission_items import MissionItem, local_xy
from fcu.feasibility import MARGIN, envelope
from fcu.mission import MissionExecutor, MissionLimits, check_mission
from fcu.tracker import pose_ref
from fcu.trajectory import make_trajectory

ROOT = Path(__file__).resolve().parents[1]
WAYPOINT, LOCAL_NED = 16, 1


def waypoints(n: int) -> tuple[MissionItem, ...]:
    """n waypoints 2 m apart, north then back, at 3 m."""
    return tuple(MissionItem(k, LOCAL_NED, WAYPOINT, int(k == 0), 1, 0.0, 0.0, 0.0, math.nan,
                             local_xy(2.0 * (k % 2 + 1)), 0, -3.0) for k in range(n))


def main() -> None:
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    limits = MissionLimits(vehicle=vehicle)
    env = envelope(vehicle)
    ex = MissionExecutor(waypoints(3), limits)
    ex.start(0.0, (0.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0))
    legs = [t1 - t0 for _, t0, t1 in ex.schedule]
    print(f"2 m legs at 2 m/s: planned {legs[1]:.3f} s and {legs[2]:.3f} s (1 s unstretched)")

    traj = make_trajectory(load_scenario(ROOT / "config/scenarios/case1_figure8.toml")
                           .trajectory)
    peak = max(env.peak(traj.sample(k * 0.01)).speed_rad_s for k in range(16001))
    print(f"Case I peak rotor speed (feed-forward, every 10 ms): {peak:.0f} rad/s, "
          f"limit {env.limit:.0f} ({MARGIN:.0%} of {vehicle.rotor_speed_max_rad_s:.0f})")

    rng = np.random.default_rng(0)
    worst = 0.0
    for q in rng.normal(size=(20000, 4)):
        q /= np.linalg.norm(q)
        worst = max(worst, env.peak(pose_ref((0.0, 0.0, 0.0), tuple(q))).speed_rad_s)
    print(f"hover at the worst of 20,000 attitudes: {worst:.0f} rad/s = "
          f"{worst / vehicle.rotor_speed_max_rad_s:.0%} of w_max")

    items = waypoints(500)
    t0 = time.perf_counter()
    result = check_mission(items, limits)
    print(f"upload check of 500 waypoints: {time.perf_counter() - t0:.3f} s "
          f"(MAV_MISSION_RESULT {result.result})")


if __name__ == "__main__":
    main()
