"""Seed campaign: Case I flown on the estimator over many sensor-noise seeds, in-process.

Each seed draws new sensor noise (mocap-indoor: IMU turn-on biases, random walks, white
noise, pose noise); the run is otherwise Case I (PID, 160 s, or `--duration`). The runs go
on a process pool. Printed: one line per seed, then the mean and the worst over the seeds of
the tracking position error (max, RMSE), the maximum attitude error and the estimation
error's RMSE (position, attitude), with how many runs completed.

    .venv/bin/python benchmarks/seed_campaign.py                     # 20 seeds, 2 workers
    .venv/bin/python benchmarks/seed_campaign.py --seeds 8 --duration 40 --workers 2
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from common.config.scenario import load_scenario
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides

ROOT = Path(__file__).resolve().parent.parent
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"

# (label, metrics path, unit scale, unit)
FIGURES = (
    ("pos max", ("position_error_m", "max"), 1e3, "mm"),
    ("pos rmse", ("position_error_m", "rmse"), 1e3, "mm"),
    ("att max", ("attitude_error_rad", "max"), 1e3, "mrad"),
    ("est pos rmse", ("estimation_error", "position_m", "rmse"), 1e3, "mm"),
    ("est att rmse", ("estimation_error", "attitude_rad", "rmse"), 1e3, "mrad"),
)


def fly(seed: int, sensors: str, controller: str, duration_s: float | None) -> dict[str, Any]:
    """One run; the metrics this campaign reports, and its wall time."""
    scenario = apply_overrides(load_scenario(CASE1), sensors=sensors, seed=seed,
                               controller=controller, duration_s=duration_s)
    t0 = time.perf_counter()
    m = run_scenario(scenario, logs=False).metrics
    out: dict[str, Any] = {"seed": seed, "status": m["status"], "failsafe": m["failsafe"],
                           "sim_time_s": m["sim_time_s"],
                           "wall_s": time.perf_counter() - t0}
    for label, path, _, _ in FIGURES:
        value: Any = m
        for key in path:
            value = value[key]
        out[label] = float(value)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20, help="how many seeds (default 20)")
    p.add_argument("--first-seed", type=int, default=0, help="the first seed (default 0)")
    p.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="fly only the first S seconds of Case I (default: all 160 s)")
    p.add_argument("--sensors", default="mocap-indoor", help="sensor profile (mocap-indoor)")
    p.add_argument("--controller", default="pid", choices=("pid", "pd"))
    args = p.parse_args()
    if args.seeds < 1 or args.workers < 1 or args.first_seed < 0:
        p.error("--seeds and --workers must be >= 1, --first-seed >= 0")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    print(f"seed campaign: Case I {args.controller}, {args.sensors}, "
          f"{args.duration or 160.0:g} s, seeds {seeds.start}..{seeds.stop - 1}, "
          f"{args.workers} workers, {os.cpu_count()} CPUs", flush=True)
    print("seed  status      " + "  ".join(f"{label + ' ' + unit:>17}"
                                           for label, _, _, unit in FIGURES)
          + "  wall s", flush=True)
    wall0 = time.perf_counter()
    rows = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        futures = [pool.submit(fly, s, args.sensors, args.controller, args.duration)
                   for s in seeds]
        for f in futures:
            r = f.result()
            rows.append(r)
            print(f"{r['seed']:4d}  {r['status']:10s}  "
                  + "  ".join(f"{r[label] * scale:17.4f}" for label, _, scale, _ in FIGURES)
                  + f"  {r['wall_s']:6.1f}", flush=True)
    wall = time.perf_counter() - wall0
    done = sum(r["status"] == "completed" for r in rows)
    print(f"\n{done}/{len(rows)} completed; {wall:.0f} s wall, "
          f"{statistics.mean(r['wall_s'] for r in rows):.1f} s per run "
          f"({rows[0]['sim_time_s']:.0f} s simulated each)")
    for label, _, scale, unit in FIGURES:
        values = [r[label] * scale for r in rows]
        worst = rows[values.index(max(values))]
        print(f"  {label:13s} mean {statistics.mean(values):8.4f} {unit:4s} "
              f"worst {max(values):8.4f} {unit:4s} (seed {worst['seed']})")
    failed = [r for r in rows if r["status"] != "completed"]
    for r in failed:
        print(f"  seed {r['seed']}: {r['status']} {r['failsafe']}")


if __name__ == "__main__":
    main()
