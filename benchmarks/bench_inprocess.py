"""In-process Case I: real-time factor (simulated seconds per wall second).

Runs the full 160 s scenario with truth sensors and the default actuators (plant at 1 kHz,
controller at 500 Hz, the whole FCU pipeline) with the logs (truth.ulg, onboard.ulg) and
without, and prints the real-time factors and the time the process spent compiling or
loading the kernels (outside wall_time_s). Target: >= 200x on a 2-core machine.

Usage: bench_inprocess.py [DURATION_S] [--logs | --no-logs] (default: both runs).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from common.config.scenario import load_scenario
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides

ROOT = Path(__file__).resolve().parent.parent


def main(duration_s: float | None = None, logs: bool = True) -> dict[str, float]:
    scenario = apply_overrides(
        load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml"),
        duration_s=duration_s)
    m = run_scenario(scenario, logs=logs).metrics
    return {"sim_time_s": m["sim_time_s"], "wall_time_s": m["wall_time_s"],
            "real_time_factor": m["real_time_factor"], "compile_time_s": m["compile_time_s"],
            "step_us": m["wall_time_s"] / max(m["samples"], 1) * 1e6,
            "position_rmse_m": m["position_error_m"]["rmse"]}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("duration", nargs="?", type=float, default=None,
                   help="simulated seconds (default: the scenario's 160 s)")
    logs = p.add_mutually_exclusive_group()
    logs.add_argument("--logs", dest="logs", action="store_const", const=(True,),
                      help="only the run with the logs")
    logs.add_argument("--no-logs", dest="logs", action="store_const", const=(False,),
                      help="only the run without the logs")
    p.set_defaults(logs=(True, False))
    return p


if __name__ == "__main__":
    args = _parser().parse_args()
    for logs in args.logs:
        r = main(args.duration, logs)
        print(f"in-process Case I ({'with' if logs else 'without'} logs): "
              f"{r['sim_time_s']:.0f} s simulated in {r['wall_time_s']:.2f} s wall = "
              f"{r['real_time_factor']:.1f}x real time, {r['step_us']:.1f} us per control step "
              f"(target >= 200x); kernels compiled or loaded in {r['compile_time_s']:.2f} s",
              flush=True)
