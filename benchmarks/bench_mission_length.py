"""The FCU's in-process control step against the mission's length: a 500-item mission and a
5-item one that fly the same flight (take-off to 1 m, a hold at the top, landing, then on the
ground, disarmed, to the end of the run).

The 500-item mission holds with 497 waypoints at the take-off's top, 0.02 s each, where the
5-item one holds with three waypoints, so every step of the 500-item mission passes about
two mission events more than the other's. Both are flown in this one run with the onboard
log (`gcs.run.inprocess.run_scenario`, the tilted vehicle, truth sensors); the FCU's step is the
pipeline's step plus the onboard log's records of it, for every control step of the run but
the first (the MISSION_START step, which plans the whole mission). Prints the median step of
each mission and their ratio, over the whole run and over the steps in flight (the rows of
`dq_onboard`). Target: ratio within 1 +- 0.10.

Usage: bench_mission_length.py [DURATION_S] [--rounds N] (default 30 s: about 13 s of
flight, 17 s on the ground; 2 runs of each mission).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import gcs.run.inprocess as inprocess
from common.config.scenario import load_scenario
from common.logs.columns import ONBOARD_COLUMNS
from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mission_items import MissionItem
from fcu.edge.onboard_log import OnboardLog
from gcs.mission_files import write_mission

ROOT = Path(__file__).resolve().parents[1]
LOCAL_NED: int = MAV_FRAME.MAV_FRAME_LOCAL_NED
TOP_Z = -1.0  # NED: 1 m up
HOLD_S = 10.0  # the hold at the top, whatever the number of items that make it


def mission(n: int) -> list[MissionItem]:
    """A take-off to 1 m, n - 2 waypoints at the top sharing HOLD_S, a landing."""
    def item(seq: int, command: int, p1: float = 0.0, z: float = TOP_Z) -> MissionItem:
        return MissionItem(seq, LOCAL_NED, command, int(seq == 0), 1, p1, 0.0, 0.0, math.nan,
                           0, 0, z)
    holds = n - 2
    return [item(0, MAV_CMD.MAV_CMD_NAV_TAKEOFF),
            *(item(k, MAV_CMD.MAV_CMD_NAV_WAYPOINT, HOLD_S / holds) for k in range(1, n - 1)),
            item(n - 1, MAV_CMD.MAV_CMD_NAV_LAND, z=0.0)]


class _TimedLog(OnboardLog):
    """The onboard log, with the time of each control step (the pipeline's `step`, then the
    log's) kept by flight time."""

    def __init__(self, sink: Any, pipeline: Any, *args: Any, **kwargs: Any) -> None:
        super().__init__(sink, pipeline, *args, **kwargs)
        self.spent_us: dict[int, float] = {}
        step = pipeline.step

        def timed_step(t_us: int, dt_s: float) -> Any:
            t0 = time.perf_counter()
            out = step(t_us, dt_s)
            self.spent_us[t_us] = (time.perf_counter() - t0) * 1e6
            return out

        pipeline.step = timed_step

    def step(self, out: Any, step_us: float, t_us: int,
             row: tuple[float, ...] | None = None) -> None:
        t0 = time.perf_counter()
        super().step(out, step_us, t_us, row)
        self.spent_us[t_us] = self.spent_us.get(t_us, 0.0) + (time.perf_counter() - t0) * 1e6


def fly(n: int, duration_s: float, folder: Path) -> dict[str, Any]:
    """The FCU's steps of the n-item mission, in microseconds, and how the run ended."""
    path = folder / f"mission_{n}.toml"
    write_mission(path, mission(n))
    base = load_scenario(ROOT / "config" / "scenarios" / "mission_tour.toml")
    scenario = dataclasses.replace(
        base, name=f"mission_{n}_items", duration_s=duration_s,
        trajectory=dataclasses.replace(base.trajectory, mission_file=str(path)))
    logs: list[_TimedLog] = []

    def timed_log(*args: Any, **kwargs: Any) -> _TimedLog:
        log = _TimedLog(*args, **kwargs)
        logs.append(log)
        return log

    original = inprocess.OnboardLog  # type: ignore[attr-defined]
    inprocess.OnboardLog = timed_log  # type: ignore[attr-defined, assignment]
    try:
        result = inprocess.run_scenario(scenario)
    finally:
        inprocess.OnboardLog = original  # type: ignore[attr-defined]
    start_us = round(result.metrics["alignment_s"] * 1e6)
    flying = {int(t) for t in result.onboard[:, ONBOARD_COLUMNS.index("time_us")]}
    spent = [(t_us, us) for t_us, us in logs[0].spent_us.items() if t_us > start_us]
    return {"steps_us": [us for _, us in spent],  # the MISSION_START step left out
            "flight_us": [us for t_us, us in spent if t_us in flying],
            "status": result.metrics["status"],
            "mission_completed": result.metrics["mission_completed"]}


def main(duration_s: float = 30.0, rounds: int = 2) -> dict[str, Any]:
    """Each mission flown `rounds` times in the order 500, 5, 5, 500, ... (a drift of the
    machine's speed weighs on both alike) after a short run that warms the caches; the
    medians are over every step of a mission's runs."""
    runs: dict[int, list[dict[str, Any]]] = {500: [], 5: []}
    with tempfile.TemporaryDirectory() as tmp:
        fly(5, 2.0, Path(tmp))
        for k in range(rounds):
            for n in ((500, 5) if k % 2 == 0 else (5, 500)):
                runs[n].append(fly(n, duration_s, Path(tmp)))
    out: dict[str, Any] = {}
    for key, n in (("long", 500), ("short", 5)):
        steps = [us for run in runs[n] for us in run["steps_us"]]
        flight = [us for run in runs[n] for us in run["flight_us"]]
        out[key] = {"median_us": statistics.median(steps), "steps": len(steps),
                    "flight_median_us": statistics.median(flight), "flight_steps": len(flight),
                    "status": sorted({run["status"] for run in runs[n]}),
                    "mission_completed": all(run["mission_completed"] for run in runs[n])}
    out["ratio"] = out["long"]["median_us"] / out["short"]["median_us"]
    out["flight_ratio"] = out["long"]["flight_median_us"] / out["short"]["flight_median_us"]
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("duration", nargs="?", type=float, default=30.0,
                   help="simulated seconds of each run (default 30)")
    p.add_argument("--rounds", type=int, default=2,
                   help="runs of each mission (default 2)")
    args = p.parse_args()
    r = main(args.duration, args.rounds)
    for key, n in (("long", 500), ("short", 5)):
        m = r[key]
        print(f"{n}-item mission: median FCU step {m['median_us']:.1f} us over {m['steps']} "
              f"steps (MISSION_START steps left out; in flight {m['flight_median_us']:.1f} us "
              f"over {m['flight_steps']}), {', '.join(m['status'])}, mission completed "
              f"{str(m['mission_completed']).lower()}")
    print(f"ratio 500 / 5 items: {r['ratio']:.3f}, in flight {r['flight_ratio']:.3f} (target "
          f"0.90-1.10: {'met' if abs(r['ratio'] - 1.0) <= 0.10 else 'missed'})", flush=True)
