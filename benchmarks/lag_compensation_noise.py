"""Case I with a noisy state: does the allocation's lag compensation (CA_LAG_COMP) pass or
amplify sensor noise?

Flies Case I in-process (gcs.run.inprocess.run_scenario: the FCU's pipeline and the plant) with
white noise added to the state the FCU sees, once with CA_LAG_COMP 0 (the paper's plain
allocation, eqs. 28-29) and once with 1 (the default: commands led for the rotor lag and the
tilt rate limit), on the same noise sequence, and prints the true tracking errors and how much
the rotor speed and tilt commands jitter (RMS of their change from one control period to the
next, and of their deviation from a 25-period moving mean).

Noise (per axis, standard deviation; seeded): position 0.5 mm, attitude 2 mrad (a rotation
vector applied in the body frame), body-frame velocity 20 mm/s, body rate 4 mrad/s plus a
constant rate bias of 2 mrad/s on each axis. The noise enters through the runner's
`state_for_fcu` (what the FCU receives over the simulator link), wrapped here.

    .venv/bin/python -m benchmarks.lag_compensation_noise [--duration S] [--seed N]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

import gcs.run.inprocess as inprocess
from common.config.scenario import load_scenario
from fcu.control.dualquat import q_mul
from fcu.stages import VehicleState
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides
from sitl.plant import PlantState

ROOT = Path(__file__).resolve().parent.parent
POSITION_M = 0.5e-3
ATTITUDE_RAD = 2e-3
VELOCITY_M_S = 20e-3
RATE_RAD_S = 4e-3
RATE_BIAS_RAD_S = 2e-3


def _rotvec_quat(phi: np.ndarray) -> tuple[float, float, float, float]:
    th = float(np.linalg.norm(phi))
    if th < 1e-12:
        return (1.0, 0.5 * float(phi[0]), 0.5 * float(phi[1]), 0.5 * float(phi[2]))
    s = math.sin(0.5 * th) / th
    return (math.cos(0.5 * th), s * float(phi[0]), s * float(phi[1]), s * float(phi[2]))


def noisy(seed: int) -> Any:
    """A `state_for_fcu` that adds the module's noise to what the FCU would see."""
    clean = inprocess.state_for_fcu
    rng = np.random.default_rng(seed)

    def state_for_fcu(s: PlantState) -> VehicleState:
        st = clean(s)
        n = rng.standard_normal(12)
        p = tuple(x + POSITION_M * e for x, e in zip(st.p_enu_m, n[0:3], strict=True))
        q = q_mul(st.q_enu_flu, _rotvec_quat(ATTITUDE_RAD * n[3:6]))
        v = tuple(x + VELOCITY_M_S * e for x, e in zip(st.v_flu_m_s, n[6:9], strict=True))
        w = tuple(x + RATE_RAD_S * e + RATE_BIAS_RAD_S
                  for x, e in zip(st.omega_flu_rad_s, n[9:12], strict=True))
        return VehicleState(p, q, v, w)

    return state_for_fcu


def _jitter(x: np.ndarray) -> tuple[float, float]:
    """RMS of the period-to-period change and of the deviation from a 25-period moving mean."""
    k = 25
    kernel = np.ones(k) / k
    smooth = np.stack([np.convolve(c, kernel, mode="same") for c in x.T], axis=1)
    core = slice(k, len(x) - k)
    return (float(np.sqrt(np.mean(np.diff(x, axis=0) ** 2))),
            float(np.sqrt(np.mean((x - smooth)[core] ** 2))))


def fly(lag_comp: float, seed: int, duration_s: float | None) -> dict[str, Any]:
    scenario = apply_overrides(load_scenario(ROOT / "config" / "scenarios" /
                                             "case1_figure8.toml"), duration_s=duration_s)
    scenario = dataclasses.replace(scenario, params={"CA_LAG_COMP": lag_comp})
    clean = inprocess.state_for_fcu
    inprocess.state_for_fcu = noisy(seed)
    try:
        result = run_scenario(scenario, logs=False)
    finally:
        inprocess.state_for_fcu = clean
    m = result.metrics
    speed = result.onboard_col(*(f"rotor_cmd{i}" for i in range(6)))
    tilt = result.onboard_col(*(f"tilt_cmd{i}" for i in range(6)))
    (sd, sm), (td, tm) = _jitter(speed), _jitter(tilt)
    return {"CA_LAG_COMP": int(lag_comp), "status": m["status"],
            "position_error_m": m["position_error_m"],
            "attitude_error_rad": m["attitude_error_rad"],
            "rotor_cmd_jitter_rad_s": {"step_rms": sd, "vs_moving_mean_rms": sm},
            "tilt_cmd_jitter_rad": {"step_rms": td, "vs_moving_mean_rms": tm}}


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=None, help="cut Case I to S seconds")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = p.parse_args(argv)
    rows = [fly(v, args.seed, args.duration) for v in (0.0, 1.0)]
    if args.json:
        print(json.dumps(rows, indent=2))
        return rows
    print(f"Case I PID, noisy state (seed {args.seed}): position 0.5 mm, attitude 2 mrad, "
          "velocity 20 mm/s, rate 4 mrad/s + 2 mrad/s bias")
    print("CA_LAG_COMP  status     pos max [mm] mean   rmse   att max [mrad] mean  rmse   "
          "rotor jitter step/local [rad/s]  tilt jitter step/local [mrad]")
    for r in rows:
        pos, att = r["position_error_m"], r["attitude_error_rad"]
        rj, tj = r["rotor_cmd_jitter_rad_s"], r["tilt_cmd_jitter_rad"]
        print(f"{r['CA_LAG_COMP']:>11}  {r['status']:<9}  {pos['max'] * 1e3:8.3f} "
              f"{pos['mean'] * 1e3:6.3f} {pos['rmse'] * 1e3:6.3f}  {att['max'] * 1e3:9.3f} "
              f"{att['mean'] * 1e3:6.3f} {att['rmse'] * 1e3:6.3f}  "
              f"{rj['step_rms']:10.3f} / {rj['vs_moving_mean_rms']:6.3f}            "
              f"{tj['step_rms'] * 1e3:8.3f} / {tj['vs_moving_mean_rms'] * 1e3:6.3f}")
    return rows


if __name__ == "__main__":
    main()
