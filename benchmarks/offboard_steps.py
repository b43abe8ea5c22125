"""Random OFFBOARD steps on both vehicle files, flown by the FCU's pipeline over the plant
in-process: how many are flown and how many refused in attitude (a tilt would flip), the
worst tracking and the longest tilt-servo rate limit over them (the property: 0 over 5 cm,
3 deg or COM_ACT_RATE_T), the approach durations, and how long the planner takes inside the
control step that sees the sample (the step's deadline is 2 ms at 500 Hz).

    .venv/bin/python -m benchmarks.offboard_steps [--count N] [--seed S]
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common.frames import enu_to_ned, q_enu_flu_to_ned_frd
from common.wire.modes import Mode
from fcu.edge.setpoint_wire import attitude_target, position_target
from tests.pipeline_flight import (
    ATTITUDE_ONLY,
    LIMIT_S,
    POSITION_ONLY,
    VEHICLES,
    Flight,
    random_step,
)


def campaign(vehicle: str, count: int, seed: int) -> dict[str, float]:
    rng = random.Random(f"{seed}-{vehicle}")
    refused = over = 0
    worst_m = worst_rad = worst_limited = 0.0
    durations, plan_ms = [], []
    t0 = time.perf_counter()
    for _ in range(count):
        p_t, q_t = random_step(rng)
        f = Flight(vehicle, (0.0, 0.0, 15.0))
        c = f.pipe.commander
        c.offboard_position(0.0, position_target(1, POSITION_ONLY, enu_to_ned(p_t), (0.0,) * 3,
                                                 (0.0,) * 3, 0.0))
        c.offboard_attitude(0.0, attitude_target(ATTITUDE_ONLY, q_enu_flu_to_ned_frd(q_t),
                                                 (0.0,) * 3))
        c.set_mode(Mode.OFFBOARD, 0.0)
        t_plan = time.perf_counter()
        f.step()  # the step that sees the sample plans the approach
        plan_ms.append((time.perf_counter() - t_plan) * 1e3)
        sp = c.modes.shaper.sp
        assert sp is not None and sp.plan is not None
        for _ in range(round((sp.plan.duration_s + 1.0) * 500)):
            f.step()
        refused += bool(sp.refused)
        durations.append(sp.plan.duration_s)
        ok = (f.pipe.armed and f.pipe.saturated_steps == 0 and f.limited_s < LIMIT_S
              and not f.reports() and f.track_m < 0.05 and f.track_rad < math.radians(3.0)
              and math.dist(f.state.p_enu_m, p_t) < 0.02)
        over += not ok
        worst_m, worst_rad = max(worst_m, f.track_m), max(worst_rad, f.track_rad)
        worst_limited = max(worst_limited, f.limited_s)
    ms = np.array(plan_ms)
    return {"count": count, "flown": count - refused, "refused": refused, "over": over,
            "worst_cm": worst_m * 100, "worst_deg": math.degrees(worst_rad),
            "limited_s": worst_limited, "d_min": min(durations), "d_med": float(
                np.median(durations)), "d_max": max(durations),
            "plan_med_ms": float(np.median(ms)), "plan_p95_ms": float(np.percentile(ms, 95)),
            "plan_max_ms": float(ms.max()), "wall_s": time.perf_counter() - t0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=100, help="steps per vehicle file")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    for vehicle in VEHICLES:
        r = campaign(vehicle, args.count, args.seed)
        print(f"{vehicle}: {r['count']} steps: {r['flown']} flown, {r['refused']} refused in "
              f"attitude, {r['over']} over a bound; worst tracking {r['worst_cm']:.2f} cm "
              f"{r['worst_deg']:.2f} deg, longest tilt rate-limited {r['limited_s']:.3f} s; "
              f"approach {r['d_min']:.1f} / {r['d_med']:.1f} / {r['d_max']:.1f} s (min / "
              f"median / max); planning step {r['plan_med_ms']:.1f} / {r['plan_p95_ms']:.1f} "
              f"/ {r['plan_max_ms']:.1f} ms (median / p95 / max); {r['wall_s']:.0f} s wall")
    return 0


if __name__ == "__main__":
    sys.exit(main())
