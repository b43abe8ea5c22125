"""Tracker + allocation step time (one 500 Hz control step of the FCU core).

Replays states near the Case I reference (perturbed by a seeded RNG) through FlightCore.step
and prints the median and p99 in microseconds. Target: median <= 50 us.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

import numpy as np

from common.config.scenario import load_scenario
from fcu.control.core import FlightCore
from fcu.control.dualquat import q_exp, q_mul
from fcu.reference.trajectory import make_trajectory
from fcu.stages import VehicleState

ROOT = Path(__file__).resolve().parent.parent


def main(steps: int = 20000) -> dict[str, float]:
    scenario = load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml")
    core = FlightCore(scenario.vehicle, scenario.gains, scenario.control_rate_hz)
    traj = make_trajectory(scenario.trajectory)
    rng = np.random.default_rng(1)
    cases = []
    for k in range(steps):
        t = 160.0 * k / steps
        ref = traj.sample(t)
        dp = rng.normal(scale=0.01, size=3)
        dq = q_exp(tuple(rng.normal(scale=0.01, size=3)))
        state = VehicleState(tuple(ref.p_enu_m[i] + dp[i] for i in range(3)),
                             q_mul(ref.q_enu_flu, dq), tuple(rng.normal(scale=0.1, size=3)),
                             tuple(rng.normal(scale=0.1, size=3)))
        cases.append((state, ref))
    clock = time.perf_counter_ns
    samples = []
    for state, ref in cases:
        t0 = clock()
        core.step(state, ref)
        samples.append((clock() - t0) / 1000.0)
    samples.sort()
    return {"median_us": statistics.median(samples),
            "p99_us": samples[math.ceil(0.99 * len(samples)) - 1],
            "steps": float(steps)}


if __name__ == "__main__":
    r = main()
    print(f"tracker+allocation step: median {r['median_us']:.1f} us, p99 {r['p99_us']:.1f} us "
          f"over {int(r['steps'])} steps (target: median <= 50 us)")
