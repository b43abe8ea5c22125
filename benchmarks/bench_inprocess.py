"""In-process Case I: real-time factor (simulated seconds per wall second).

Runs the full 160 s scenario with the default actuators (plant at 1 kHz, controller at
500 Hz) and prints the real-time factor. Target: >= 20x on a 2-core machine.
"""

from __future__ import annotations

import sys
from pathlib import Path

from common.config import load_scenario
from gcs.inprocess import apply_overrides, run_scenario

ROOT = Path(__file__).resolve().parent.parent


def main(duration_s: float | None = None) -> dict[str, float]:
    scenario = apply_overrides(
        load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml"),
        duration_s=duration_s)
    m = run_scenario(scenario).metrics
    return {"sim_time_s": m["sim_time_s"], "wall_time_s": m["wall_time_s"],
            "real_time_factor": m["real_time_factor"],
            "position_rmse_m": m["position_error_m"]["rmse"]}


if __name__ == "__main__":
    r = main(float(sys.argv[1]) if len(sys.argv) > 1 else None)
    print(f"in-process Case I: {r['sim_time_s']:.0f} s simulated in {r['wall_time_s']:.2f} s "
          f"wall = {r['real_time_factor']:.1f}x real time (target >= 20x)")
