"""Every phase of a mission, at random: `--count` missions per vehicle (hexa_tilted,
hexa_planar), each written to a file in one of the formats users upload (the project's TOML,
QGC WPL with local positions, QGC WPL with global positions, a QGC .plan), read back as a user's
file is, and flown in-process from the ground, or refused by the FCU with a reason.

    .venv/bin/python benchmarks/phase_missions.py --count 1000 --workers 2

A second generator beside benchmarks/random_mission_gen.py (whose missions are cruise legs,
keyframes and figures from home): this one is built phase by phase, and draws what that one
never does. Mission k of seed S comes from numpy's default_rng((S, k, vehicle)):

- a start on the ground at home, or (half the missions) up to 5 m from it;
- a take-off to 0.2-3 m (uniform), at MIS_TKO_SPD 0.5-3 m/s;
- 1-4 middle phases, each one of: a cruise leg (0.3-4 m in a random direction, up to 1 m up
  or down, a yaw or not, a hold of 0-1 s), the same after a DO_CHANGE_SPEED (ground speed
  0.3-3 m/s, or -1 no change, or -2 the default; sometimes a climb or descent speed), a loiter
  (0.5-2 s), a keyframe (0.5-3 m, a turn of up to 0.6 rad, in 1-8 s: the user's duration, so it
  may be refused), a touch-and-go (NAV_LAND, then a take-off to 0.2-3 m);
- a landing at MIS_LAND_SPD 0.05-5 m/s (log-uniform), the touchdown through to disarm.

PROPERTY of a flown mission (truth sensors): status `completed` (not `limited`), the largest
position error <= 5 cm and attitude error <= 3 deg over the rows metrics.json counts (its
`error_rows` rule), every touchdown under 1 m/s, and every tilt servo within its rate limit
(the truth log's tilt angles, sample to sample: never at the limit for RATE_LIMITED_S,
COM_ACT_RATE_T's 0.1 s, the FCU monitor's rate-limited episode). PROPERTY of a refusal: it names a
MAV_MISSION_RESULT, the item, and a reason. Per phase (the item active at each row, from the
FCU's own plan from the start pose): the rows flown, the worst position error and the fastest
servo. Exit 0 only if both properties hold everywhere.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.random_missions import base_scenario, fcu_limits, schedule
from common.config.scenario import Scenario, TrajectoryConfig
from common.quaternion import angle_between_rows
from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mission_items import PX4_SITL_HOME, MissionItem, local_xy
from fcu.compose import published_home
from gcs.mission_files import read_mission, write_mission
from gcs.mission_files.frames import to_frame
from gcs.run.inprocess import InProcessError, run_scenario

VEHICLES = ("hexa_tilted", "hexa_planar")
FORMATS = ("toml", "wpl", "wpl-global", "plan")
POS_MAX_M = 0.05
ATT_MAX_DEG = 3.0
TOUCHDOWN_MAX_M_S = 1.0
RATE_LIMITED_S = 0.1  # a servo at its rate this long is rate-limited (COM_ACT_RATE_T)
TAIL_S = 4.0  # flown after the planned end: the touchdown, the land detector, the disarm
MAX_PLAN_S = 200.0  # longer plans are counted apart, not flown
LOCAL = MAV_FRAME.MAV_FRAME_LOCAL_NED
REFUSAL = re.compile(r"MAV_MISSION_[A-Z_0-9]+: item \d+: \S")


# ------------------------------------------------------------------ the generator


class Draw:
    """One mission's items, built phase by phase (local NED, metres)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.items: list[MissionItem] = []
        self.phases: list[str] = []  # the phase of each item
        self.ned = [0.0, 0.0, 0.0]

    def add(self, phase: str, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0,
            p4: float = math.nan, ned: tuple[float, float, float] | None = None,
            frame: int = LOCAL) -> None:
        n, e, d = ned if ned is not None else (0.0, 0.0, 0.0)
        seq = len(self.items)
        self.items.append(MissionItem(seq, frame, command, int(seq == 0), 1, p1, p2, p3, p4,
                                      local_xy(n), local_xy(e), d))
        self.phases.append(phase)

    def takeoff(self, phase: str) -> None:
        self.ned[2] = -float(self.rng.uniform(0.2, 3.0))
        self.add(phase, MAV_CMD.MAV_CMD_NAV_TAKEOFF, ned=(0.0, 0.0, self.ned[2]))

    def leg(self, phase: str = "cruise") -> None:
        r = self.rng
        dist, heading = r.uniform(0.3, 4.0), r.uniform(-math.pi, math.pi)
        self.ned[0] += dist * math.cos(heading)
        self.ned[1] += dist * math.sin(heading)
        self.ned[2] = min(-0.3, self.ned[2] + float(r.uniform(-1.0, 1.0)))
        yaw = float(r.uniform(-180.0, 180.0)) if r.random() < 0.3 else math.nan
        self.add(phase, MAV_CMD.MAV_CMD_NAV_WAYPOINT, p1=float(r.choice([0.0, 0.5, 1.0])),
                 p4=yaw, ned=(self.ned[0], self.ned[1], self.ned[2]))

    def speed_change(self) -> None:
        r = self.rng
        kind = int(r.choice([1, 1, 0, 2, 3]))
        speed = float(r.choice([r.uniform(0.3, 3.0), r.uniform(0.3, 3.0), -1.0, -2.0]))
        self.add("speed", MAV_CMD.MAV_CMD_DO_CHANGE_SPEED, p1=kind, p2=speed, p3=-1.0,
                 frame=MAV_FRAME.MAV_FRAME_MISSION)
        self.leg("cruise after a speed change")

    def loiter(self) -> None:
        self.add("loiter", MAV_CMD.MAV_CMD_NAV_LOITER_TIME, p1=float(self.rng.uniform(0.5, 2.0)),
                 ned=(self.ned[0], self.ned[1], self.ned[2]))

    def keyframe(self) -> None:
        r = self.rng
        dist, heading = r.uniform(0.5, 3.0), r.uniform(-math.pi, math.pi)
        self.ned[0] += dist * math.cos(heading)
        self.ned[1] += dist * math.sin(heading)
        turn = r.normal(0.0, 1.0, 3)
        turn *= r.uniform(0.0, 0.6) / max(float(np.linalg.norm(turn)), 1e-9)
        self.add("keyframe", 31000, p1=float(r.uniform(1.0, 8.0)), p2=float(turn[0]),
                 p3=float(turn[1]), p4=float(turn[2]), ned=(self.ned[0], self.ned[1],
                                                           self.ned[2]))

    def touch_and_go(self) -> None:
        self.add("touch-and-go", MAV_CMD.MAV_CMD_NAV_LAND, p4=math.nan)
        self.takeoff("touch-and-go")

    def land(self) -> None:
        self.add("landing", MAV_CMD.MAV_CMD_NAV_LAND, p4=math.nan)


def draw_mission(seed: int, k: int, vehicle: str) -> dict[str, Any]:
    """Mission k of campaign `seed` for `vehicle`: items, phases, start, speeds, format."""
    rng = np.random.default_rng((seed, k, VEHICLES.index(vehicle)))
    d = Draw(rng)
    start = (0.0, 0.0, 0.0)
    if rng.random() < 0.5:
        r, a = 5.0 * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
        start = (r * math.cos(a), r * math.sin(a), 0.0)  # ENU, on the ground
    d.takeoff("take-off")
    middle = [d.leg, d.speed_change, d.loiter, d.keyframe, d.touch_and_go]
    for _ in range(int(rng.integers(1, 5))):
        middle[int(rng.integers(len(middle)))]()
    d.land()
    return {"items": d.items, "phases": d.phases, "start_enu_m": start,
            "land_m_s": float(math.exp(rng.uniform(math.log(0.05), math.log(5.0)))),
            "takeoff_m_s": float(rng.uniform(0.5, 3.0)),
            "format": FORMATS[int(rng.integers(len(FORMATS)))]}


def written(items: list[MissionItem], fmt: str, folder: Path) -> Path:
    """The mission as a user's file of that format (global positions through the default
    home for `wpl-global` and `plan`)."""
    home = published_home(PX4_SITL_HOME)
    if fmt == "toml":
        path = folder / "mission.toml"
        write_mission(path, items, "toml")
    elif fmt == "wpl":
        path = folder / "mission.waypoints"
        write_mission(path, items, "wpl")
    else:
        path = folder / ("mission.plan" if fmt == "plan" else "mission.waypoints")
        write_mission(path, to_frame(items, "global", home), "plan" if fmt == "plan" else "wpl",
                      home)
    return path


# ------------------------------------------------------------------ one flight


def _scenario(vehicle: str, m: dict[str, Any], path: Path, duration_s: float) -> Scenario:
    base = base_scenario(vehicle)
    traj = TrajectoryConfig(kind="mission", position_enu_m=m["start_enu_m"],
                            mission_file=str(path))
    return dataclasses.replace(
        base, trajectory=traj, duration_s=duration_s, initial_position_enu_m=m["start_enu_m"],
        params={**base.params, "MIS_LAND_SPD": m["land_m_s"], "MIS_TKO_SPD": m["takeoff_m_s"]})


def fly(job: tuple[int, int, str]) -> dict[str, Any]:
    """Draw, write, read back, plan, fly and judge one mission."""
    seed, k, vehicle = job
    m = draw_mission(seed, k, vehicle)
    out: dict[str, Any] = {"k": k, "vehicle": vehicle, "format": m["format"],
                           "land_m_s": m["land_m_s"], "start_m": math.hypot(*m["start_enu_m"][:2]),
                           "phases": sorted(set(m["phases"]))}
    with tempfile.TemporaryDirectory() as tmp:
        path = written(m["items"], m["format"], Path(tmp))
        items = read_mission(path)
        probe = _scenario(vehicle, m, path, 1.0)
        limits = fcu_limits(probe)
        try:
            plan = schedule([it for it in items], limits, m["start_enu_m"])
        except ValueError:
            plan = ()
        end_s = plan[-1][2] if plan else 1.0
        if end_s > MAX_PLAN_S:
            out["outcome"] = "long"
            return out
        try:
            r = run_scenario(_scenario(vehicle, m, path, end_s + TAIL_S), logs=False)
        except InProcessError as exc:
            text = str(exc)
            out.update(outcome="refused", reason=text, reason_ok=bool(REFUSAL.search(text)))
            return out
    out.update(judge(r, plan, m, limits.vehicle))
    return out


def judge(r: Any, plan: tuple[tuple[int, float, float], ...], m: dict[str, Any],
          vehicle: Any) -> dict[str, Any]:
    metrics = r.metrics
    t_truth, t_onboard = r.truth_col("time_us")[:, 0], r.onboard_col("time_us")[:, 0]
    rows = np.isin(t_truth, t_onboard)  # truth rows matched on time_us with the onboard's
    keep = np.isin(t_onboard, t_truth)
    t = t_truth[rows] * 1e-6
    p = r.truth_col("px", "py", "pz")[rows]
    pd = r.onboard_col("pdx", "pdy", "pdz")[keep]
    q = r.truth_col("qw", "qx", "qy", "qz")[rows]
    qd = r.onboard_col("qdw", "qdx", "qdy", "qdz")[keep]
    landed = r.truth_col("landed")[rows, 0] > 0.5
    counted = ~(landed & (pd[:, 2] < 0.0))  # metrics.json's rule
    pos = np.linalg.norm(p - pd, axis=1)
    att = np.degrees(angle_between_rows(q, qd))
    tilts = r.truth_col(*(f"tilt{i}" for i in range(6)))[rows]
    rate = np.zeros(len(t))
    rate[1:] = (np.abs(np.diff(tilts, axis=0)) / np.diff(t)[:, None]).max(axis=1)
    vz = r.truth_col("vz")[rows, 0]
    contacts = [float(vz[i - 1]) for i in range(1, len(t)) if landed[i] and not landed[i - 1]]
    phase = np.full(len(t), "landing", dtype=object)  # after the plan: the touchdown
    for seq, t0, t1 in plan:
        phase[(t >= t0) & (t < t1)] = m["phases"][seq]
    if m["start_enu_m"] != (0.0, 0.0, 0.0):
        phase[(phase == "take-off")] = "take-off away from home"
    per_phase: dict[str, dict[str, float]] = {}
    for name in set(phase):
        sel = (phase == name) & counted
        if sel.any():
            per_phase[str(name)] = {"rows": int(sel.sum()), "pos_m": float(pos[sel].max()),
                                    "att_deg": float(att[sel].max()),
                                    "servo_rad_s": float(rate[phase == name].max())}
    at_limit = rate >= vehicle.tilt_rate_max_rad_s * 0.999
    longest, run = 0.0, 0.0
    dt = np.diff(t, prepend=t[0])
    for hit, step in zip(at_limit, dt, strict=True):
        run = run + step if hit else 0.0
        longest = max(longest, run)
    ok = (metrics["status"] == "completed" and metrics["position_error_m"]["max"] <= POS_MAX_M
          and math.degrees(metrics["attitude_error_rad"]["max"]) <= ATT_MAX_DEG
          and all(abs(v) < TOUCHDOWN_MAX_M_S for v in contacts) and longest < RATE_LIMITED_S)
    return {"outcome": "flown", "ok": bool(ok), "status": metrics["status"],
            "at_limit_s": longest,
            "pos_m": metrics["position_error_m"]["max"],
            "att_deg": math.degrees(metrics["attitude_error_rad"]["max"]),
            "servo_rad_s": float(rate.max()), "contacts": contacts, "per_phase": per_phase}


# ------------------------------------------------------------------ the campaign


def summary(results: list[dict[str, Any]], wall_s: float) -> tuple[str, bool]:
    lines = [f"# Phase missions: {len(results)} missions, {wall_s:.0f} s wall", ""]
    ok = True
    for vehicle in VEHICLES:
        rs = [x for x in results if x["vehicle"] == vehicle]
        outcomes = Counter(x["outcome"] for x in rs)
        flown = [x for x in rs if x["outcome"] == "flown"]
        bad = [x for x in flown if not x["ok"]]
        silent = [x for x in rs if x["outcome"] == "refused" and not x["reason_ok"]]
        ok = ok and not bad and not silent
        lines += [f"## {vehicle}: {len(rs)} missions",
                  f"- flown {outcomes['flown']}, refused {outcomes['refused']}, planned "
                  f"beyond {MAX_PLAN_S:.0f} s (not flown) {outcomes['long']}",
                  f"- accepted over the property: {len(bad)}; refusals without an item and "
                  f"a reason: {len(silent)}",
                  f"- formats: {dict(Counter(x['format'] for x in rs))}"]
        for x in bad[:10]:
            lines.append(f"  - over the property: k = {x['k']} status {x['status']} pos "
                         f"{x['pos_m']:.4f} m att {x['att_deg']:.2f} deg servo "
                         f"{x['servo_rad_s']:.2f} rad/s ({x['at_limit_s']:.3f} s at the "
                         f"limit) contacts {x['contacts']}")
        for x in silent[:10]:
            lines.append(f"  - refusal without a reason: k = {x['k']}: {x['reason']}")
        reasons = Counter(re.sub(r"[0-9.]+", "#", x["reason"].split(": item")[0])
                          for x in rs if x["outcome"] == "refused")
        lines.append(f"- refusals by kind: {dict(reasons)}")
        table: dict[str, list[float]] = {}
        for x in flown:
            for name, f in x["per_phase"].items():
                row = table.setdefault(name, [0, 0, 0.0, 0.0, 0.0])
                row[0] += 1
                row[1] += f["rows"]
                row[2] = max(row[2], f["pos_m"])
                row[3] = max(row[3], f["att_deg"])
                row[4] = max(row[4], f["servo_rad_s"])
        lines += ["", "| phase | missions | rows | worst position m | worst attitude deg | "
                  "fastest servo rad/s |", "|---|---:|---:|---:|---:|---:|"]
        for name in sorted(table):
            n, rows, pos, att, servo = table[name]
            lines.append(f"| {name} | {n:.0f} | {rows:.0f} | {pos:.4f} | {att:.3f} | "
                         f"{servo:.2f} |")
        if flown:
            lines.append(f"\nlongest time a servo spent at its rate limit: "
                         f"{max(x['at_limit_s'] for x in flown):.3f} s")
        land = [x["land_m_s"] for x in flown]
        if land:
            lines.append(f"\nland speeds flown: {min(land):.2f}-{max(land):.2f} m/s; "
                         f"touchdowns: fastest "
                         f"{max((abs(v) for x in flown for v in x['contacts']), default=0):.2f} "
                         "m/s")
        lines.append("")
    return "\n".join(lines), ok


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--count", type=int, default=100, help="missions per vehicle")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("runs/phase_missions"))
    args = ap.parse_args(argv)
    jobs = [(args.seed, k, v) for v in VEHICLES for k in range(args.count)]
    start = time.monotonic()
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(fly, jobs, chunksize=4))
    text, ok = summary(results, time.monotonic() - start)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.jsonl").write_text("".join(json.dumps(x) + "\n" for x in results))
    (args.out / "summary.md").write_text(text)
    print(text)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
