"""Full-stack lockstep: Case I through sitl + fcu processes over UDP (truth sensors), with the
simulator link's round trip measured between those two processes in the same run.

Before the flight the FCU times RTT_PROBES TIMESYNC round trips with the SITL on the
simulator link's own sockets (`udp_rtt_us` in metrics.json, the median); the run then gives
the wall time per control step (`step_wall_us`). Printed: both, their ratio (target <= 1.5),
the real-time factor, and where a step's wall time goes in each process (means per step;
`wait` is the time spent waiting for the other process and the transport).

    python -m benchmarks.bench_lockstep [DURATION_S] [--repeat N]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
from pathlib import Path
from typing import Any

from common.config.scenario import load_scenario
from gcs.run.process_run import one_vehicle, run_processes

ROOT = Path(__file__).resolve().parent.parent
TARGET_RATIO = 1.5


def run_once(duration_s: float | None = None) -> dict[str, Any]:
    scenario = load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml")
    if duration_s is not None:
        scenario = dataclasses.replace(scenario, duration_s=duration_s)
    with tempfile.TemporaryDirectory() as tmp:
        m = one_vehicle(run_processes(scenario, Path(tmp)))
    rtt = m["fcu"].get("sim_rtt") or {}
    return {"status": m["status"], "real_time_factor": m["real_time_factor"],
            "sim_time_s": m["sim_time_s"], "wall_time_s": m["wall_time_s"],
            "step_wall_us": m["step_wall_us"], "udp_rtt_us": m["udp_rtt_us"],
            "rtt_p10_us": rtt.get("p10_us"), "rtt_p90_us": rtt.get("p90_us"),
            "step_per_rtt": m["step_per_rtt"], "fcu_step_p50_us": m["fcu_step_us"]["p50"],
            "stages_us": m.get("step_stages_us", {})}


def main(duration_s: float | None = None) -> dict[str, Any]:
    """One run (the figures of that run; kept for `benchmarks.run_all`)."""
    return run_once(duration_s)


def report(r: dict[str, Any]) -> None:
    print(f"lockstep Case I through processes over UDP ({r['status']}): "
          f"{r['sim_time_s']:.0f} s simulated in {r['wall_time_s']:.1f} s = "
          f"{r['real_time_factor']:.1f}x real time")
    ratio = r["step_per_rtt"]
    print(f"  per control step {r['step_wall_us']:.1f} us wall; udp_rtt_us "
          f"{r['udp_rtt_us']:.1f} (p10 {r['rtt_p10_us']:.1f}, p90 {r['rtt_p90_us']:.1f}); "
          f"ratio {ratio:.2f} (target <= {TARGET_RATIO}: "
          f"{'met' if ratio <= TARGET_RATIO else 'not met'}); "
          f"FCU step p50 {r['fcu_step_p50_us']:.1f} us")
    for proc, stages in r["stages_us"].items():
        busy = sum(v for k, v in stages.items() if k != "wait")
        parts = ", ".join(f"{k} {v:.1f}" for k, v in stages.items())
        print(f"  {proc:4s} us per step: {parts} (busy {busy:.1f})")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("duration_s", type=float, nargs="?", default=None,
                    help="cut Case I to this many seconds (default: all 160 s)")
    ap.add_argument("--repeat", type=int, default=1, help="runs (the median ratio is shown)")
    args = ap.parse_args()
    runs = []
    for _ in range(max(1, args.repeat)):
        runs.append(run_once(args.duration_s))
        report(runs[-1])
    if len(runs) > 1:
        print(f"median over {len(runs)} runs: ratio "
              f"{statistics.median(r['step_per_rtt'] for r in runs):.2f}, real-time factor "
              f"{statistics.median(r['real_time_factor'] for r in runs):.1f}x")
