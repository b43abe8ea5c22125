"""The FCU with its estimator, through processes: the control step's compute time in real
time (target p99 <= 250 us at 500 Hz; the step time includes the estimator's work on the
period's IMU samples and poses) and the lockstep real-time factor of Case I beside the
exact-state (`truth`) run's; then in-process (`gcs run --in-process`): the real-time factor
of the whole Case I (160 s), from a run as `gcs run` flies it, and the thread CPU time the
estimator's calls took, from a second run that times them (timing its 370,000 calls made a
mocap run about a quarter slower, so that run's pace is not the one reported).

    .venv/bin/python benchmarks/bench_estimator_fcu.py [--duration S] [--in-process-only]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from common.config.scenario import load_scenario
from common.config.sensors import resolve_sensor_profile
from fcu.estimator.ekf import Estimator
from gcs.report.run_metrics import RunMetrics
from gcs.run.inprocess import run_scenario
from gcs.run.process_run import one_vehicle, run_processes

ROOT = Path(__file__).resolve().parent.parent
CASE1 = ROOT / "config/scenarios/case1_figure8.toml"


def in_process(profile: str) -> tuple[RunMetrics, float]:
    """(metrics, thread CPU seconds of the whole run) of the whole Case I in-process with
    `profile`, logs written as `gcs run` writes them. The run's CPU time is the figure a busy
    machine changes least."""
    sc = dataclasses.replace(load_scenario(CASE1), sensors=resolve_sensor_profile(profile))
    cpu0 = time.thread_time()
    metrics = run_scenario(sc).metrics
    return metrics, time.thread_time() - cpu0


def estimator_calls(profile: str) -> tuple[float, int]:
    """(thread CPU seconds in the estimator's calls, calls) of the whole Case I in-process
    with `profile`, each call timed."""
    spent = [0.0, 0]
    clock = time.thread_time
    originals = {name: getattr(Estimator, name)
                 for name in ("on_imu", "on_pose", "output", "health", "status")}

    def timed(fn: Any) -> Any:
        def call(self: Estimator, *a: Any) -> Any:
            t0 = clock()
            r = fn(self, *a)
            spent[0] += clock() - t0
            spent[1] += 1
            return r
        return call

    for name, fn in originals.items():
        setattr(Estimator, name, timed(fn))
    try:
        run_scenario(dataclasses.replace(load_scenario(CASE1),
                                         sensors=resolve_sensor_profile(profile)))
    finally:
        for name, fn in originals.items():
            setattr(Estimator, name, fn)
    return float(spent[0]), int(spent[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run")
    ap.add_argument("--in-process-only", action="store_true",
                    help="only the in-process runs of the whole Case I")
    args = ap.parse_args()
    base = dataclasses.replace(load_scenario(CASE1), duration_s=args.duration)
    print(f"machine: {os.cpu_count()} cores, load average "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for profile in ("truth", "mocap-indoor"):
        m, cpu_s = in_process(profile)
        est_s, calls = estimator_calls(profile) if profile != "truth" else (0.0, 0)
        print(f"{profile:13s} in-process: {m['real_time_factor']:5.2f}x real time "
              f"({m['sim_time_s']:.0f} s in {m['wall_time_s']:.1f} s; "
              f"{m['sim_time_s'] / cpu_s:5.2f}x of its thread CPU, {cpu_s:.1f} s), estimator "
              f"calls {est_s:.2f} s thread CPU over {calls} calls, status {m['status']}")
    if args.in_process_only:
        return
    with tempfile.TemporaryDirectory() as tmp:
        for profile in ("truth", "mocap-indoor"):
            sc = dataclasses.replace(base, sensors=resolve_sensor_profile(profile))
            rt = one_vehicle(run_processes(sc, Path(tmp) / f"rt_{profile}", realtime=True))
            ls = one_vehicle(run_processes(sc, Path(tmp) / f"ls_{profile}"))
            step = rt["fcu_step_us"]
            print(f"{profile:13s} real time: step p50 {step['p50']:6.1f} us  p99 "
                  f"{step['p99']:6.1f} us  max {step['max']:7.1f} us  deadline misses "
                  f"{rt['deadline_misses']}  status {rt['status']}")
            print(f"{profile:13s} lockstep:  {ls['real_time_factor']:5.2f}x real time, "
                  f"step p50 {ls['fcu_step_us']['p50']:6.1f} us, status {ls['status']}, "
                  f"max position error {ls['position_error_m']['max'] * 1e3:.3f} mm")


if __name__ == "__main__":
    main()
