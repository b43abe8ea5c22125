"""The compiled flight core per 500 Hz control step: tracker (eq. 16) + allocation (eqs.
28-29) with lag compensation (CA_LAG_COMP = 1, the FCU's default) + two 1 kHz plant
substeps, each a kernel call on flat arrays as the in-process runner makes them.

Replays states near the Case I reference (perturbed by a seeded RNG) and prints the median
and p99 in microseconds, and the time this process spent compiling or loading the kernels.
Target: median <= 4 us.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

import numpy as np

from common.config.scenario import load_scenario
from common.process.startup import compile_time_s
from fcu.control.core import FlightCore
from fcu.control.dualquat import q_exp, q_mul
from fcu.reference.trajectory import make_trajectory
from sitl.plant import STATE_SIZE, Plant, state_row

ROOT = Path(__file__).resolve().parent.parent


def main(steps: int = 20000) -> dict[str, float]:
    scenario = load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml")
    t0 = time.perf_counter()
    core = FlightCore(scenario.vehicle, scenario.gains, scenario.control_rate_hz,
                      lag_compensation=True)
    plant = Plant(scenario.vehicle, dt_us=1_000_000 // scenario.physics_rate_hz)
    warm_s = time.perf_counter() - t0
    traj = make_trajectory(scenario.trajectory)
    rng = np.random.default_rng(1)
    cases = []
    for k in range(steps):
        ref = traj.sample(160.0 * k / steps)
        dp = rng.normal(scale=0.01, size=3)
        dq = q_exp(tuple(rng.normal(scale=0.01, size=3)))
        x = np.array((*(ref.p_enu_m[i] + dp[i] for i in range(3)), *q_mul(ref.q_enu_flu, dq),
                      *rng.normal(scale=0.1, size=6), *ref.p_enu_m, *ref.q_enu_flu,
                      *ref.v_enu_m_s, *ref.a_enu_m_s2, *ref.omega_flu_rad_s,
                      *ref.omega_dot_flu_rad_s2))
        cases.append(x)
    row = state_row(plant.initial_state((0.0, 0.0, 5.0), on_ground=False))
    sub = np.empty((2, STATE_SIZE))
    cmd = np.empty(12)
    inp = core.inp
    clock = time.perf_counter_ns
    samples = []
    for x in cases:
        t_start = clock()
        inp[0:32] = x
        out = core.step_arrays(core.dt_s)
        cmd[0:6] = out[36:42]  # led speeds
        cmd[6:12] = out[48:54]  # led tilts
        plant.step_rows(row, cmd, sub)
        samples.append((clock() - t_start) / 1000.0)
    samples.sort()
    return {"median_us": statistics.median(samples),
            "p99_us": samples[math.ceil(0.99 * len(samples)) - 1],
            "steps": float(steps), "warm_up_s": warm_s, "compile_time_s": compile_time_s()}


if __name__ == "__main__":
    r = main()
    print(f"flight core (tracker + allocation + lag compensation + 2 plant substeps): median "
          f"{r['median_us']:.2f} us, p99 {r['p99_us']:.2f} us per control step over "
          f"{int(r['steps'])} steps (target: median <= 4 us); kernels compiled or loaded in "
          f"{r['compile_time_s']:.2f} s")
