"""The FCU with its estimator, through processes: the control step's compute time in real
time (target p99 <= 250 us at 500 Hz; the step time includes the estimator's work on the
period's IMU samples and poses) and the lockstep real-time factor of Case I beside the
exact-state (`truth`) run's; then in-process (`gcs run --in-process`): the real-time factor
of the whole Case I (160 s), from a run as `gcs run` flies it, and the thread CPU time the
estimator's calls took, from a second run that times them (timing its 370,000 calls made a
mocap run about a quarter slower, so that run's pace is not the one reported).

The real-time step times follow the shared host's speed, which moves within seconds: each
real-time run is preceded by a one-second reading of it (`host_speed.py`'s loop: the median
ms a pass; about 6-7 ms is the host at its usual speed, 10-15 ms slow), and `--repeat N`
flies the real-time runs N times, then prints each profile's p99 over the runs and how many
met the target.

    .venv/bin/python benchmarks/bench_estimator_fcu.py [--duration S]
        [--in-process-only | --real-time-only] [--repeat N]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.host_speed import one_pass
from common.config.scenario import load_scenario
from common.config.sensors import resolve_sensor_profile
from fcu.estimator.ekf import Estimator
from gcs.report.run_metrics import RunMetrics
from gcs.run.inprocess import run_scenario
from gcs.run.process_run import one_vehicle, run_processes

ROOT = Path(__file__).resolve().parent.parent
CASE1 = ROOT / "config/scenarios/case1_figure8.toml"
STEP_P99_TARGET_US = 250.0  # real time with mocap-indoor


def host_reading(seconds: float = 1.0) -> float:
    """The host's speed now: the median ms of `host_speed.one_pass` over `seconds`."""
    end = time.monotonic() + seconds
    passes = [one_pass()]
    while time.monotonic() < end:
        passes.append(one_pass())
    return statistics.median(passes) * 1e3


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
    only = ap.add_mutually_exclusive_group()
    only.add_argument("--in-process-only", action="store_true",
                      help="only the in-process runs of the whole Case I")
    only.add_argument("--real-time-only", action="store_true",
                      help="only the runs through processes (real time and lockstep)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="fly the real-time runs this many times (then a summary)")
    args = ap.parse_args()
    if not args.duration > 0.0:
        ap.error(f"--duration must be > 0, got {args.duration}")
    if args.repeat < 1:
        ap.error(f"--repeat must be >= 1, got {args.repeat}")
    base = dataclasses.replace(load_scenario(CASE1), duration_s=args.duration)
    print(f"machine: {os.cpu_count()} cores, load average "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if not args.real_time_only:
        for profile in ("truth", "mocap-indoor"):
            m, cpu_s = in_process(profile)
            est_s, calls = estimator_calls(profile) if profile != "truth" else (0.0, 0)
            print(f"{profile:13s} in-process: {m['real_time_factor']:5.2f}x real time "
                  f"({m['sim_time_s']:.0f} s in {m['wall_time_s']:.1f} s; "
                  f"{m['sim_time_s'] / cpu_s:5.2f}x of its thread CPU, {cpu_s:.1f} s), "
                  f"estimator calls {est_s:.2f} s thread CPU over {calls} calls, status "
                  f"{m['status']}")
    if args.in_process_only:
        return
    p99s: dict[str, list[float]] = {"truth": [], "mocap-indoor": []}
    with tempfile.TemporaryDirectory() as tmp:
        for n in range(args.repeat):
            for profile in p99s:
                sc = dataclasses.replace(base, sensors=resolve_sensor_profile(profile))
                host_ms = host_reading()
                rt = one_vehicle(run_processes(sc, Path(tmp) / f"rt_{profile}_{n}",
                                               realtime=True))
                step = rt["fcu_step_us"]
                p99s[profile].append(step["p99"])
                print(f"{profile:13s} real time: step p50 {step['p50']:6.1f} us  p99 "
                      f"{step['p99']:6.1f} us  max {step['max']:7.1f} us  deadline misses "
                      f"{rt['deadline_misses']}  status {rt['status']}  (host {host_ms:.2f} "
                      f"ms a pass before)")
                if n == 0:
                    ls = one_vehicle(run_processes(sc, Path(tmp) / f"ls_{profile}"))
                    print(f"{profile:13s} lockstep:  {ls['real_time_factor']:5.2f}x real time, "
                          f"step p50 {ls['fcu_step_us']['p50']:6.1f} us, status "
                          f"{ls['status']}, max position error "
                          f"{ls['position_error_m']['max'] * 1e3:.3f} mm")
    if args.repeat > 1:
        for profile, values in p99s.items():
            met = sum(v <= STEP_P99_TARGET_US for v in values)
            print(f"{profile:13s} real time over {len(values)} runs: step p99 median "
                  f"{statistics.median(values):.1f} us (min {min(values):.1f}, max "
                  f"{max(values):.1f})" + (f", {met} of {len(values)} at <= "
                                           f"{STEP_P99_TARGET_US:.0f} us"
                                           if profile == "mocap-indoor" else ""))


if __name__ == "__main__":
    main()
