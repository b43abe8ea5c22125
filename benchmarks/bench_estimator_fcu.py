"""The FCU with its estimator, through processes: the control step's compute time in real
time (target p99 <= 150 us at 500 Hz; the step time includes the estimator's work on the
period's IMU samples and poses) and the lockstep real-time factor of Case I beside the
exact-state (`truth`) run's.

    .venv/bin/python benchmarks/bench_estimator_fcu.py [--duration S]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
from pathlib import Path

from common.config import load_scenario
from common.sensors_config import resolve_sensor_profile
from gcs.process_run import run_processes

ROOT = Path(__file__).resolve().parent.parent
CASE1 = ROOT / "config/scenarios/case1_figure8.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run")
    args = ap.parse_args()
    base = dataclasses.replace(load_scenario(CASE1), duration_s=args.duration)
    print(f"machine: {os.cpu_count()} cores, load average "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        for profile in ("truth", "mocap-indoor"):
            sc = dataclasses.replace(base, sensors=resolve_sensor_profile(profile))
            rt = run_processes(sc, Path(tmp) / f"rt_{profile}", realtime=True)
            ls = run_processes(sc, Path(tmp) / f"ls_{profile}")
            step = rt["fcu_step_us"]
            print(f"{profile:13s} real time: step p50 {step['p50']:6.1f} us  p99 "
                  f"{step['p99']:6.1f} us  max {step['max']:7.1f} us  deadline misses "
                  f"{rt['deadline_misses']}  status {rt['status']}")
            print(f"{profile:13s} lockstep:  {ls['real_time_factor']:5.2f}x real time, "
                  f"step p50 {ls['fcu_step_us']['p50']:6.1f} us, status {ls['status']}, "
                  f"max position error {ls['position_error_m']['max'] * 1e3:.3f} mm")


if __name__ == "__main__":
    main()
